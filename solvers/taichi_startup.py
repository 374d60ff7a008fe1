"""Four costs Taichi 1.7 pays in every process for nothing: three avoided before any kernel is
defined (the first before Taichi is imported), the fourth (``skip_code_generation_passes``) when
the runtime starts on the CPU.

All are start-up time only: what Taichi caches is unchanged, and so is every result its kernels
compute (4. changes the machine code a load makes, not its arithmetic). They touch Taichi 1.7
internals, which is why pyproject.toml pins taichi 1.7.* (as for solvers/launch.py).

1. Defining a kernel or ti.func: Taichi's decorator asks ``inspect.getframeinfo`` whether the
   definition sits in a class body, looking two frames up. For a function defined at a module's
   top level that frame is importlib's ``<frozen importlib._bootstrap>``, a file ``inspect`` cannot
   find, so it scans every loaded module (thousands, with torch) on each definition: ~1–1.5 s of
   importing genesis_lite (measured, ~500 definitions), and 0.13 of the 0.26 s Taichi's own import
   takes after torch's (its own definitions): so this is done before Taichi is imported. Telling
   ``inspect`` which module that file is (the true answer) makes the lookup a dictionary hit; the
   answer, "not in a class", is the same.
2. Transforming a kernel's Python AST, which Taichi does in every process even when its offline
   cache holds the compiled kernel: for every AST node it writes where the node lies in the source
   (for a compile error's message and the IR's debug info), wrapping the source and caret lines
   with ``textwrap`` — 40–50 % of the transform (measured: ~2 of the ~7 s a two-link pendulum's
   contact kernels take at build). ``_source_position`` writes the same text, unwrapped, by
   concatenation. It does not enter the offline cache's keys.
3. The same transform reads each ti.func's source from its file (``inspect``: find the module,
   tokenize the file to find the function's block) every time a kernel inlines the function —
   thousands of times for the contact kernels (~1 s of an example's start-up, measured under
   cProfile: 2.5 of 22 s). A function's source does not change while the process runs: it is read
   once per function. Each read's lines are then passed through ``textwrap.fill`` (tabs expanded,
   the newline dropped), again at every inlining: remembered per line (a Panda's kernel
   transforms 1.26–1.34 → 1.21–1.23 s).
4. Loading a kernel from the offline cache: Taichi caches the kernel's LLVM IR after its O3
   pipeline and the loop strength reduction (and three cleanup passes) it runs after it
   (``optimize_module`` in codegen_cpu.cpp), and every process turns the cached IR into machine
   code with LLVM's code generator, whose IR passes run loop strength reduction again. On our
   kernels (index arithmetic of the arenas in nested loops) that second pass and the scalar evolution it queries were most of the load: profiled,
   ~55 % of a quadruped's first backward. Its code generation is told to skip it (LLVM's
   ``-disable-lsr``; the strength reduction done before caching stays): a KUKA's first backward
   7.6–8.6 → 2.6 s, a quadruped's 27 → 5.3–6.0 s of CPU, warm cache. The option is set through
   LLVM's C API entry ``LLVMParseCommandLineOptions``, which Taichi's library holds but does not
   export: its address is read from the library's ELF symbol table (~20 ms; ~1 s the first time
   after a reboot, reading 28 MB of the library's tables from disk). The same call skips X86
   domain reassignment (``-disable-x86-domain-reassignment``), a pass of code generation for
   AVX-512 machines that moves scalar integer logic into mask registers: ~9 % of the library's
   time in an a1 quadruped's fresh process, its first step 1.8–1.9 → 1.4–1.6 s (float64, warm
   cache), its run time unchanged within the noise (a1 at 1 and 256 envs, boxes at 1024, KUKA at
   1024, old and new alternating: 2026-11-28). And it skips the scheduler that runs after register
   allocation (``-post-RA-scheduler=false``; an out-of-order core reorders the instructions anyway):
   ~0.1 of the ~1.6 s code generation takes in a fresh a1 process (LLVM's -time-passes), fresh
   processes (old and new alternating, three rounds) a1 3.59–3.87 → 3.38–3.59 s, KUKA 2.46–2.47 →
   2.26–2.38 s; run time unchanged (a1 at 1 and 64 envs, same bits), where a smaller budget for
   the register allocator's region splitting (``-grow-region-complexity-budget``), which saved
   0.3 s more on a Panda, cost the a1's contact step ~2 %.
"""
import ctypes
import functools
import inspect
import mmap
import sys
import textwrap
import weakref

# (1. below; before Taichi's own import, which defines its functions the same way)
inspect.modulesbyfile.setdefault("<frozen importlib._bootstrap>", "importlib._bootstrap")

import numpy as np  # noqa: E402

from taichi.lang import kernel_impl  # noqa: E402
from taichi.lang.ast.ast_transformer_utils import ASTTransformerContext  # noqa: E402


def _source_position(context, node):
    """Where ``node`` of the kernel or ti.func being transformed lies: its file, line and function,
    the source line and a caret under the node (its first line where it spans several)."""
    line = context.src[node.lineno - 1]
    start = context.indent + node.col_offset
    end = context.indent + node.end_col_offset if node.end_lineno == node.lineno else len(line)
    return (f'File "{context.file}", line {node.lineno + context.lineno_offset}, in {context.func.func.__name__}:\n'
            f'{line}\n{" " * start}{"^" * max(end - start, 1)}\n')


def _once_per_function(read):
    """``read(function)``, computed once per function object (held weakly: a function that is gone
    leaves the cache). The transform copies the lines it is given before changing them, so one
    answer can serve every call."""
    answers = weakref.WeakKeyDictionary()

    @functools.wraps(read)
    def once(function):
        if function not in answers:
            answers[function] = read(function)
        return answers[function]

    return once


ASTTransformerContext.get_pos_info = _source_position
kernel_impl.getsourcefile = _once_per_function(kernel_impl.getsourcefile)
kernel_impl.getsourcelines = _once_per_function(kernel_impl.getsourcelines)


class _SourceLines:
    """``textwrap`` as the transform uses it (kernel_impl's module global), ``fill`` remembered per
    line and arguments (3. above)."""
    dedent = staticmethod(textwrap.dedent)
    fill = staticmethod(functools.lru_cache(maxsize=None)(textwrap.fill))


kernel_impl.textwrap = _SourceLines


_ELF_SYMBOL = np.dtype([("name", "<u4"), ("info", "u1"), ("other", "u1"), ("section", "<u2"), ("value", "<u8"),
                        ("size", "<u8")])


def _symbol_values(path, names):
    """{name: (value, file offset)} of the symbols ``names`` defined in the ELF64 (little-endian)
    shared library at ``path``, from its full symbol table (.symtab; names it does not define are
    left out). The file offset is where the symbol's bytes lie in the file (None for a symbol of
    a section the file holds no bytes of, as .bss)."""
    def read(file, offset, size):
        file.seek(offset)
        return file.read(size)

    with open(path, "rb") as file:
        header = read(file, 0, 64)
        if header[:6] != b"\x7fELF\x02\x01":
            return {}
        table, (entry_size, count) = int.from_bytes(header[40:48], "little"), np.frombuffer(header[58:62], "<u2")
        sections = np.frombuffer(read(file, table, int(entry_size) * int(count)), np.uint8).reshape(count, -1)
        field = lambda start, size: sections[:, start:start + size].copy().view(f"<u{size}")[:, 0]  # noqa: E731
        kinds, addresses, offsets, sizes, links = field(4, 4), field(16, 8), field(24, 8), field(32, 8), field(40, 4)
        symtab = np.flatnonzero(kinds == 2)  # SHT_SYMTAB: absent from a stripped library
        if len(symtab) != 1:
            return {}
        symtab, strtab = int(symtab[0]), int(links[symtab[0]])
        symbols = np.frombuffer(read(file, int(offsets[symtab]), int(sizes[symtab])), _ELF_SYMBOL)
        with mmap.mmap(file.fileno(), 0, access=mmap.ACCESS_READ) as image:
            start, end = int(offsets[strtab]), int(offsets[strtab] + sizes[strtab])
            places = {name: image.find(b"\0" + name.encode() + b"\0", start - 1, end) for name in names}
    values = {}
    for name, at in places.items():
        found = symbols[(symbols["name"] == at + 1 - start) & (symbols["section"] != 0)] if at >= 0 else ()
        if len(found) == 1:
            value, section = int(found["value"][0]), int(found["section"][0])
            in_file = section < len(kinds) and kinds[section] != 8  # (SHT_NOBITS: no bytes in the file)
            values[name] = (value, value - int(addresses[section]) + int(offsets[section]) if in_file else None)
    return values


def skip_code_generation_passes():
    """Tell the LLVM inside Taichi's library not to run loop strength reduction, X86 domain
    reassignment nor the scheduler after register allocation when it generates machine code (4.
    above): once per process, from the CPU runtime's first start (``gs.init``), before any kernel
    is loaded. It holds for the whole process, every Taichi kernel (a user's own too) and later
    runtimes (Taichi's CUDA path adds its own strength reduction pass, which stays). Does nothing
    where the library is not the one this reads (another platform, a stripped build, another LLVM,
    a file replaced since it was loaded): loads are then as slow as before, nothing else."""
    library = sys.modules.get("taichi._lib.core.taichi_python")
    if library is None or getattr(library, "_code_generation_passes_skipped", False):
        return
    library._code_generation_passes_skipped = True
    try:
        entry = _loaded_entry(library.__file__)
    except Exception:  # (a speed-up only: whatever fails, Taichi runs as it would)
        return
    if entry is not None:  # (LLVM's C entry ignores an option its build lacks, and applies the others)
        entry(len(_SKIPPED_PASSES), (ctypes.c_char_p * len(_SKIPPED_PASSES))(*_SKIPPED_PASSES), None)


_SKIPPED_PASSES = (b"genesis_lite", b"-disable-lsr", b"-disable-x86-domain-reassignment",
                   b"-post-RA-scheduler=false")  # (argv[0] first)


def _loaded_entry(path):
    """LLVMParseCommandLineOptions of the library loaded from ``path`` as a ctypes function, or
    None: its address is the exported PyInit_taichi_python's (the load base) moved by the two
    symbols' distance in the file's symbol table, and its first bytes in memory must be those the
    file holds there (the file is the loaded library). _ZL10DisableLSR is the option's object:
    without it this LLVM has no such option (it would ignore it)."""
    wanted = ("PyInit_taichi_python", "LLVMParseCommandLineOptions", "_ZL10DisableLSR")
    symbols = _symbol_values(path, wanted)
    if len(symbols) != len(wanted) or symbols["LLVMParseCommandLineOptions"][1] is None:
        return None
    exported = ctypes.cast(ctypes.CDLL(path).PyInit_taichi_python, ctypes.c_void_p).value
    (init, _), (parse, in_file) = symbols["PyInit_taichi_python"], symbols["LLVMParseCommandLineOptions"]
    address = exported - init + parse
    with open(path, "rb") as file:
        file.seek(in_file)
        if file.read(32) != ctypes.string_at(address, 32):
            return None
    return ctypes.CFUNCTYPE(None, ctypes.c_int, ctypes.POINTER(ctypes.c_char_p), ctypes.c_char_p)(address)

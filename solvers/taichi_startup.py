"""Three costs Taichi 1.7 pays in every process for nothing, avoided before any kernel is defined.

Both are start-up time only: what Taichi compiles, caches and runs is unchanged. They touch
Taichi 1.7 internals, which is why pyproject.toml pins taichi 1.7.* (as for solvers/launch.py).

1. Defining a kernel or ti.func: Taichi's decorator asks ``inspect.getframeinfo`` whether the
   definition sits in a class body, looking two frames up. For a function defined at a module's
   top level that frame is importlib's ``<frozen importlib._bootstrap>``, a file ``inspect`` cannot
   find, so it scans every loaded module (thousands, with torch) on each definition: ~1–1.5 s of
   importing genesis_lite (measured, ~500 definitions). Telling ``inspect`` which module that file
   is (the true answer) makes the lookup a dictionary hit; the answer, "not in a class", is the same.
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
   once per function.
"""
import functools
import inspect
import weakref

from taichi.lang import kernel_impl
from taichi.lang.ast.ast_transformer_utils import ASTTransformerContext


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


inspect.modulesbyfile.setdefault("<frozen importlib._bootstrap>", "importlib._bootstrap")
ASTTransformerContext.get_pos_info = _source_position
kernel_impl.getsourcefile = _once_per_function(kernel_impl.getsourcefile)
kernel_impl.getsourcelines = _once_per_function(kernel_impl.getsourcelines)

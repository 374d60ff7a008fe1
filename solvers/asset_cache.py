"""A disk cache of what reading assets computes: a URDF file's links (rigid/urdf.py), a mesh file's
triangles and a mesh's mass properties (rigid/shapes.py), a mesh's convex hull
(rigid/collision/convex.py).

Why: a fresh process that builds a robot it has built before then neither imports yourdfpy,
trimesh and scipy (~0.6 s, scipy most of it) nor runs qhull again. A KUKA arm's fresh process
(import, build, first step; warm kernel cache) took 3.5 s, 2.6 s with it (measured, 2-core
EPYC). Genesis keeps such a cache too (~/.cache/genesis).

An entry is a pickle named by the SHA-256 of everything its computation reads: its input (a
file's bytes or path, the arguments), the source files of the modules that compute it and the
versions of the packages they call, so that an edit to any of them makes a new entry rather than
reading a stale one. The other files a computation reads (a URDF's meshes, a mesh file named by
its path) are listed in the entry with their size and modification time: a change to any makes
the entry a miss. Nothing is stored for a computation that raises.

Where: ``$GENESIS_LITE_CACHE_DIR``, else ``$XDG_CACHE_HOME/genesis_lite``, else
``~/.cache/genesis_lite``; ``GENESIS_LITE_CACHE_DIR=""`` turns the cache off. Delete the folder to
empty it. It is a speed-up only: a folder that cannot be written, or an entry that cannot be
read, is passed over.
"""
import contextlib
import functools
import hashlib
import importlib.metadata
import os
import pickle
import tempfile

_FORMAT = b"genesis_lite asset cache 1"


def folder() -> str | None:
    """The cache's folder, or None when it is turned off."""
    chosen = os.environ.get("GENESIS_LITE_CACHE_DIR")
    if chosen is not None:
        return chosen or None
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "genesis_lite")


def load_or_compute(kind: str, inputs: list, compute, sources: tuple, packages: tuple):
    """The value of ``compute()`` for ``inputs``: from the cache, or computed and stored.

    kind: the entry's folder ("urdf", "mesh", "mass", "hull"); inputs: bytes, everything the computation
    depends on besides the files it names; compute() → (value, files): the value (picklable, not None) and
    the paths of the other files it read; sources: the paths of the modules that compute it;
    packages: the names of the installed packages it calls.
    """
    where = folder()
    if where is None:
        return compute()[0]
    path = os.path.join(where, kind, _digest(kind, inputs, sources, packages) + ".pkl")
    entry = _read(path)
    if entry is not None:
        return entry
    value, files = compute()
    _write(path, (value, _stats(files)))
    return value


def _digest(kind: str, inputs: list, sources: tuple, packages: tuple) -> str:
    """Hex SHA-256 of the format, the kind, the inputs, the sources' bytes and the packages' versions."""
    digest = hashlib.sha256(_FORMAT)
    for part in [kind.encode(), *inputs, _code_digest(tuple(sources), tuple(packages))]:
        digest.update(len(part).to_bytes(8, "little"))  # (lengths first: no two lists join alike)
        digest.update(part)
    return digest.hexdigest()


@functools.lru_cache(maxsize=None)
def _code_digest(sources: tuple, packages: tuple) -> bytes:
    """SHA-256 of the source files' bytes and the packages' versions (read once a process)."""
    digest = hashlib.sha256()
    for source in sources:
        with open(source, "rb") as file:
            digest.update(file.read())
    for package in packages:
        try:
            digest.update(f"{package} {importlib.metadata.version(package)}".encode())
        except importlib.metadata.PackageNotFoundError:
            digest.update(f"{package} absent".encode())
    return digest.digest()


def _stats(files) -> list:
    """(path, size, modification time ns) of each file."""
    out = []
    for file in files:
        stat = os.stat(file)
        out.append((os.fspath(file), stat.st_size, stat.st_mtime_ns))
    return out


def _read(path: str):
    """The value stored at ``path``, or None when there is none, it cannot be read, or a file it
    was computed from has changed since."""
    try:
        with open(path, "rb") as file:
            value, stats = pickle.load(file)
        return value if _stats(stat[0] for stat in stats) == stats else None
    except Exception:  # (absent, unreadable, from another pickle protocol, a file gone: a miss)
        return None


def _write(path: str, entry) -> None:
    """Store ``entry`` at ``path`` (written aside, then renamed: a reader never sees half of it)."""
    try:
        os.makedirs(os.path.dirname(path), exist_ok=True)
        handle, temporary = tempfile.mkstemp(dir=os.path.dirname(path), suffix=".tmp")
    except OSError:  # (read-only, a file where the folder should be: not stored)
        return
    try:
        with os.fdopen(handle, "wb") as file:
            pickle.dump(entry, file, protocol=pickle.HIGHEST_PROTOCOL)
        os.replace(temporary, path)
    except OSError:  # (a full disk: not stored)
        with contextlib.suppress(OSError):
            os.unlink(temporary)

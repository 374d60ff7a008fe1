"""A disk cache of what reading assets computes: a URDF file's links (rigid/urdf.py), a mesh file's
triangles and a mesh's mass properties (rigid/shapes.py), a mesh's convex hull
(rigid/collision/convex.py).

Why: a fresh process that builds a robot it has built before then neither imports yourdfpy,
trimesh and scipy (~0.6 s, scipy most of it) nor runs qhull again. A KUKA arm's fresh process
(import, build, first step; warm kernel cache) took 3.5 s, 2.5 s with it (measured, 2-core
EPYC). Genesis keeps such a cache too (~/.cache/genesis).

An entry is a pickle named by the SHA-256 of its input (a file's bytes or path, the
arguments), the source files of the modules that compute it and the
versions of the packages they call, so that an edit to any of them makes a new entry rather than
reading a stale one. The other files a computation reads (a URDF's meshes, a mesh file named by
its path) are listed in the entry as they were before it read them (``snapshot``: size, times,
inode), and so are the places a URDF's mesh was looked for first and not found: a change to any
makes the entry a miss. Nothing is stored for a computation that raises, nor for one that read a
mesh file of a format that may name other files (glTF's buffers, COLLADA's images: their changes
would go unseen; shapes.SELF_CONTAINED_MESH lists the formats kept).

Where: ``$GENESIS_LITE_CACHE_DIR``, else ``$XDG_CACHE_HOME/genesis_lite``, else
``~/.cache/genesis_lite``; ``GENESIS_LITE_CACHE_DIR=""`` turns the cache off. Delete the folder to
empty it (nothing is ever evicted). It is a speed-up only: a folder that cannot be written, or
an entry that cannot be read, is passed over. Entries are pickles, which run code when read:
point it only at a folder you trust, as Taichi's cache (which holds machine code).
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

    kind: the entry's folder ("urdf", "mesh", "mass", "hull"); inputs: bytes, everything the
    computation depends on besides the files it names; compute() → (value, files): the value
    (picklable, not None) and the ``snapshot``s of the other files it read (or looked for), each
    taken before reading the file; files None: the value is not to be stored (it read a file
    that may name further files); sources: the paths of the modules that compute it; packages:
    the names of the installed packages it calls.
    """
    where = folder()
    if where is None:
        return compute()[0]
    path = os.path.join(where, kind, _digest(kind, inputs, sources, packages) + ".pkl")
    entry = _read(path)
    if entry is not None:
        return entry
    value, files = compute()
    if files is not None:
        _write(path, (value, files))
    return value


def snapshot(path) -> tuple:
    """(path, identity) of a file as it is now: its size, modification and change times and inode
    (None when it does not exist). The change time cannot be set back (``cp -p``, ``rsync -a``
    and ``tar`` restore the modification time), so a rewritten file differs even at the same size
    and modification time."""
    try:
        stat = os.stat(path)
    except OSError:
        return os.fspath(path), None
    return os.fspath(path), (stat.st_size, stat.st_mtime_ns, stat.st_ctime_ns, stat.st_ino)


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


def _read(path: str):
    """The value stored at ``path``, or None when there is none, it cannot be read, or a file it
    was computed from has changed since."""
    try:
        with open(path, "rb") as file:
            value, files = pickle.load(file)
        return value if all(snapshot(name) == (name, identity) for name, identity in files) else None
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

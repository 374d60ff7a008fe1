"""One namespace: solvers/ installs as genesis_lite.solvers, nothing else lands at the top level,
and imports run one way, from the API package to the solvers."""
import ast
import os
import pathlib
import shutil
import subprocess
import sys
import zipfile

ROOT = pathlib.Path(__file__).resolve().parent.parent


def test_wheel_installs_only_genesis_lite(tmp_path):
    """The wheel (built from a copy of the source tree, which it leaves untouched) holds every
    module of genesis_lite/ and solvers/ and the assets genesis_lite ships, all under genesis_lite/:
    no top-level 'solvers'."""
    source = tmp_path / "source"
    shutil.copytree(ROOT, source, ignore=shutil.ignore_patterns(".git", "build", "*.egg-info", "__pycache__",
                                                               ".pytest_cache"))
    # built as pip builds it, with pyproject.toml's build requirements (not whatever setuptools
    # this environment happens to have)
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp_path), str(source)],
                   check=True, capture_output=True, timeout=300)
    (wheel,) = tmp_path.glob("genesis_lite-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    tops = {name.split("/")[0] for name in names}
    assert {t for t in tops if not t.endswith(".dist-info")} == {"genesis_lite"}, sorted(tops)
    expected = {f"genesis_lite/{path.relative_to(ROOT / 'genesis_lite').as_posix()}"
                for path in (ROOT / "genesis_lite").rglob("*.py")}
    expected |= {f"genesis_lite/solvers/{path.relative_to(ROOT / 'solvers').as_posix()}"
                 for path in (ROOT / "solvers").rglob("*.py")}
    assert expected <= names, f"modules missing from the wheel: {sorted(expected - names)}"
    assets = {f"genesis_lite/{path.relative_to(ROOT / 'genesis_lite').as_posix()}"
              for path in (ROOT / "genesis_lite" / "assets").rglob("*") if path.is_file()}
    assert "genesis_lite/assets/urdf/drones/cf2x.urdf" in assets
    assert assets <= names, f"assets missing from the wheel: {sorted(assets - names)}"


def test_solvers_import_first_outside_the_source_tree(tmp_path):
    """``import genesis_lite.solvers.rigid.solver`` as a first import works from any folder, and
    no module called ``solvers`` is importable there (a user's own ``solvers`` stays theirs)."""
    code = ("import importlib.util, genesis_lite.solvers.rigid.solver as s; "
            "assert importlib.util.find_spec('solvers') is None; print(s.RigidSolver.__name__)")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    result = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True,
                            timeout=120, env=env)
    assert result.returncode == 0, result.stderr[-2000:]
    assert result.stdout.strip().endswith("RigidSolver")


def _imported_modules(path):
    """(module, level) of every import statement in the file."""
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            yield from ((alias.name, 0) for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            yield node.module or "", node.level


def test_solvers_never_import_the_api():
    """Every import in solvers/ is relative (within the solvers) or a third-party package."""
    files = sorted((ROOT / "solvers").rglob("*.py"))
    assert len(files) > 10
    for path in files:
        for module, level in _imported_modules(path):
            depth = len(path.relative_to(ROOT / "solvers").parts) - 1  # folders below solvers/
            assert level <= depth + 1, f"{path}: a relative import leaves the solvers package"
            if level == 0:
                assert module.split(".")[0] not in ("genesis_lite", "solvers"), f"{path} imports {module}"

"""Shared test configuration: one BLAS thread, headless matplotlib, common fixtures."""

import os
import sys

# One BLAS thread, for this process and the notebook kernels and CLI subprocesses it starts
# (set before numpy is imported; an explicit setting is kept): the tests' matrices are small,
# and OpenBLAS's extra threads spin -- on the shared 2-core machine they doubled the CPU time
# of the FEM tests (measured: 12.7 s CPU alone, 4.9 s with one thread, for the same test)
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

# Byte-code caching on, for this process and the CLI subprocesses and notebook kernel it
# starts: with PYTHONDONTWRITEBYTECODE set (as on the shared machines) every process compiles
# coilrod's sources again, and pytest rewrites every test module's asserts on every run
# (collection: 7.2 s CPU without the cache, 3.6 s with it)
sys.dont_write_bytecode = False
os.environ.pop("PYTHONDONTWRITEBYTECODE", None)

import matplotlib  # noqa: E402

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

import coilrod.rod._compiled  # noqa: E402
import coilrod.rod._compiled_spatial  # noqa: E402
import coilrod.rod._inertia  # noqa: E402
import coilrod.rod._mixed_newton  # noqa: E402
import coilrod.rod._planar_newton  # noqa: E402
import coils.coaxial  # noqa: E402

# The suite compiles every kernel anyway (far-field, error and large-grid tests need them), so
# the numpy passes that run in a fresh process until compiling pays (the ski-rental rule,
# README "Cold start") would only add their budgets to a cold run: compile at the first call.
# The tests of that rule set these themselves; CLI subprocesses and the notebook kernel keep
# the defaults.
for _module in (
    coils.coaxial,
    coilrod.rod._compiled,
    coilrod.rod._compiled_spatial,
    coilrod.rod._inertia,
    coilrod.rod._planar_newton,
):
    _module.COMPILE_AFTER = 0.0
# ... except the mixed layout's Newton corrector (~10 s of CPU to compile): the suite runs the
# engine's numpy corrector in its place (the kernel is tested through .py_func), unless numba's
# cache holds it
coilrod.rod._mixed_newton.COMPILE_AFTER = np.inf


@pytest.fixture
def rng():
    """A seeded random generator, so failures reproduce."""
    return np.random.default_rng(20261122)


@pytest.fixture
def denied(monkeypatch):
    """Simulated permissions, the same for root (which chmod does not restrict, and CI runs
    as root): ``denied(path)`` makes the folder ``path`` read-only -- ``os.access`` says
    no write, creating anything inside raises PermissionError -- and ``denied(path,
    read=True)`` makes the file ``path`` unreadable (``Path.read_bytes``/``read_text`` and
    ``open`` raise PermissionError)."""
    import builtins
    import errno
    import os
    from pathlib import Path

    folders: list[Path] = []
    files: set[Path] = set()

    def error(path):
        return PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(path))

    def inside(path) -> bool:
        path = Path(os.path.abspath(path))
        return any(path != f and path.is_relative_to(f) for f in folders)

    real_access, real_mkdir, real_open = os.access, Path.mkdir, builtins.open
    real_read_bytes, real_read_text = Path.read_bytes, Path.read_text
    real_mkstemp = __import__("tempfile")._mkstemp_inner

    def access(path, mode, *args, **kwargs):
        if mode & os.W_OK and Path(os.path.abspath(path)) in folders:
            return False
        return real_access(path, mode, *args, **kwargs)

    def mkdir(self, *args, **kwargs):
        if inside(self):
            raise error(self)
        return real_mkdir(self, *args, **kwargs)

    def open_(file, mode="r", *args, **kwargs):
        if isinstance(file, str | os.PathLike):
            if Path(os.path.abspath(file)) in files or (set(mode) & set("wax+") and inside(file)):
                raise error(file)
        return real_open(file, mode, *args, **kwargs)

    def read_bytes(self):
        if Path(os.path.abspath(self)) in files:
            raise error(self)
        return real_read_bytes(self)

    def read_text(self, *args, **kwargs):
        if Path(os.path.abspath(self)) in files:
            raise error(self)
        return real_read_text(self, *args, **kwargs)

    def mkstemp_inner(dir, pre, suf, flags, output_type):
        if inside(os.path.join(dir, "x")):
            raise error(dir)
        return real_mkstemp(dir, pre, suf, flags, output_type)

    monkeypatch.setattr(os, "access", access)
    monkeypatch.setattr(Path, "mkdir", mkdir)
    monkeypatch.setattr(builtins, "open", open_)
    monkeypatch.setattr(Path, "read_bytes", read_bytes)
    monkeypatch.setattr(Path, "read_text", read_text)
    monkeypatch.setattr("tempfile._mkstemp_inner", mkstemp_inner)

    def deny(path, read: bool = False):
        path = Path(os.path.abspath(path))
        (files.add(path) if read else folders.append(path))
        return path

    return deny

"""numba's on-disk cache, guarded (coils._numba_cache.guard): a damaged entry is a warning and
a recompile, never a crash inside numba nor a changed byte of machine code run.

Nothing is compiled here: entries are written and read through numba's own cache objects (the
kernel's ``_cache``), with a made-up payload where numba would store a compiled result.  That
a real kernel compiles anew after its data file was truncated, garbled or had one byte flipped
(and gives the same numbers) was checked by hand in fresh processes (CHANGELOG, h-brk3).
"""

import pickle
import sys
from pathlib import Path

import numba
import numpy as np
import pytest
from numba.core import caching, config, types
from numba.core.registry import cpu_target
from scipy.constants import mu_0

import coils._numba_cache as nc


def twice(x):
    return 2.0 * x


@pytest.fixture
def kernel(tmp_path, monkeypatch):
    """A cached kernel of this module (not compiled) with its cache in ``tmp_path``."""
    monkeypatch.setattr(config, "CACHE_DIR", str(tmp_path))  # what NUMBA_CACHE_DIR sets
    k = numba.njit(cache=True)(twice)
    assert tmp_path in Path(k._cache._cache_file._index_path).parents
    return k


def _entry(kernel, payload=("payload",)):
    """Write ``payload`` as the cache entry of ``kernel`` for one float argument, as numba
    saves a compiled result; returns (signature, target context, data file path)."""
    sig, ctx = (types.float64,), cpu_target.target_context
    kernel._cache._impl.locator.ensure_cache_path()
    key = kernel._cache._index_key(sig, ctx.codegen())
    cache_file = kernel._cache._cache_file
    cache_file.save(key, payload)
    return sig, ctx, Path(cache_file._data_path(cache_file._load_index()[key]))


def test_every_cached_kernel_of_coils_and_coilrod_is_guarded():
    # the guard is installed when numba is imported or defines a kernel, whichever module of
    # ours comes first: every cached dispatcher in our modules carries it
    import coilrod.contact._compiled_search  # noqa: F401
    import coilrod.rod._compiled_contact  # noqa: F401
    import coils._compiled  # noqa: F401

    GuardedCache, GuardedFile = nc._guarded_types()
    found = []
    for name, module in list(sys.modules.items()):
        if module is None or name.partition(".")[0] not in ("coils", "coilrod"):
            continue
        for value in vars(module).values():
            if isinstance(value, numba.core.dispatcher.Dispatcher) and value._can_compile:
                if isinstance(value._cache, caching.FunctionCache):
                    found.append((name, value.__name__))
                    assert type(value._cache) is GuardedCache, (name, value)
                    assert type(value._cache._cache_file) is GuardedFile, (name, value)
    assert ("coils.loop", "loop_point") in found
    assert len(found) >= 10, found


def test_a_damaged_data_file_is_a_warning_and_a_miss(kernel):
    sig, ctx, data = _entry(kernel)  # unguarded: numba's own file format
    raw = data.read_bytes()
    data.write_bytes(raw[: len(raw) // 2])
    with pytest.raises(pickle.UnpicklingError):  # numba's own loader: raised inside the call
        kernel._cache.load_overload(sig, ctx)
    nc.guard(kernel)
    with pytest.warns(RuntimeWarning, match=r"data file of twice '.*\.nbc' is damaged.*trunc"):
        assert kernel._cache.load_overload(sig, ctx) is None  # numba: compile anew
    assert not data.exists()
    # an intact entry numba wrote unguarded: nothing vouches for its machine code, so it is a
    # miss too, without a warning (RuntimeWarnings are errors in this suite)
    _entry(kernel)
    data.write_bytes(raw)
    assert kernel._cache._cache_file.load(kernel._cache._index_key(sig, ctx.codegen())) is None


def test_a_sealed_data_file_with_one_byte_changed_is_never_used(kernel):
    nc.guard(kernel)
    payload = ("payload", 1.5, b"machine code")
    sig, ctx, data = _entry(kernel, payload)
    cache_file = kernel._cache._cache_file
    assert cache_file._load_data(data.name) == payload
    # numba unguarded (an older coilrod sharing the cache) still reads the sealed file
    assert caching.IndexDataCacheFile._load_data(cache_file, data.name) == payload
    raw = bytearray(data.read_bytes())
    at = raw.index(b"machine code")
    raw[at] ^= 0x20  # still a valid pickle, of another payload
    data.write_bytes(bytes(raw))
    assert caching.IndexDataCacheFile._load_data(cache_file, data.name)[2] == b"Machine code"
    with pytest.warns(RuntimeWarning, match=r"damaged \(its SHA-256 does not match"):
        assert kernel._cache.load_overload(sig, ctx) is None
    assert not data.exists()


def test_an_entry_numba_cannot_rebuild_is_a_warning_and_a_miss(kernel):
    nc.guard(kernel)
    sig, ctx, data = _entry(kernel, ("not", "a compiled result"))  # sealed, intact
    with pytest.warns(RuntimeWarning, match=r"data file of twice .* is damaged \(TypeError"):
        assert kernel._cache.load_overload(sig, ctx) is None
    assert not data.exists()


def test_coaxial_compiling_anyway_goes_through_the_rental(monkeypatch):
    # a point the numpy pass leaves (far zone) runs the compiled pass at once: that buys
    # through the rental (which checks numba's cache first), not by setting its flag; the
    # field is the on-axis closed form.  The suite compiles the pass anyway (conftest)
    import math

    import coils
    import coils.coaxial as cx
    from coils._compiled import coaxial_field

    checked = []
    monkeypatch.setattr(nc, "_check_index", checked.append)
    monkeypatch.setattr(cx._rental, "held", lambda: False)
    monkeypatch.setattr(cx._rental, "spent", 0.0)
    monkeypatch.setattr(cx._rental, "ready", False)
    monkeypatch.setattr(cx, "COMPILE_AFTER", math.inf)
    pair = coils.HelmholtzPair(0.1, 50, 2.0, axis="z")
    B = pair.B([[0.0, 0.0, 1.0]])
    assert cx._rental.ready
    assert checked == [coaxial_field]
    z0, a, current = pair.filaments.T  # on the axis: mu0 I a^2 / (2 ((z - z0)^2 + a^2)^1.5)
    Bz = np.sum(mu_0 * current * a**2 / (2 * ((1.0 - z0) ** 2 + a**2) ** 1.5))
    np.testing.assert_allclose(B[0], [0, 0, Bz], rtol=1e-14, atol=0)

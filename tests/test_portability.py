"""Results that must not depend on the instruction set: the arctangent by which every
direction is binned (``trig.atan2_portable``), and bins and tallies compared bitwise between
this process and one with NumPy's AVX-512 dispatch disabled and numba's target pinned to
Haswell (AVX2), i.e. the two paths an AVX2 and an AVX-512 machine take."""

from __future__ import annotations

import io
import math
import os
import subprocess
import sys

import dispatch_probe
import numpy as np
import pytest

from microsim import trig
from microsim.sim import paths


def _ulps(a: float, b: float) -> float:
    return abs(a - b) / np.spacing(max(abs(a), abs(b), np.finfo(float).tiny))


def test_atan2_portable_is_libm_within_an_ulp_with_c99_special_values():
    """``atan2_portable`` (fdlibm) is within 1 ulp of libm's atan2 on random and octant-edge
    arguments, and has C99's values at signed zeros, infinities and NaN."""
    rng = np.random.default_rng(7)
    y = np.concatenate([rng.normal(size=20_000), rng.normal(size=2000) * 1e-300, [1.0, -1.0]])
    x = np.concatenate([rng.normal(size=20_000), rng.normal(size=2000) * 1e300, [1.0, -1.0]])
    a = np.linspace(-np.pi, np.pi, 4001)
    y, x = np.concatenate([y, np.sin(a), 3 * x]), np.concatenate([x, np.cos(a), 2 * y])
    worst = max(_ulps(trig.atan2_portable(p, q), math.atan2(p, q)) for p, q in zip(y, x))
    assert worst <= 1.0
    inf, pi = math.inf, math.pi
    special = [  # a list: 0.0 and -0.0 are the same dict key
        (0.0, 0.0, 0.0), (-0.0, 0.0, -0.0), (0.0, -0.0, pi), (-0.0, -0.0, -pi),
        (0.0, -1.0, pi), (-0.0, -1.0, -pi), (0.0, 2.0, 0.0), (1.0, 0.0, pi / 2),
        (-1.0, -0.0, -pi / 2), (inf, inf, pi / 4), (inf, -inf, 3 * pi / 4),
        (-inf, 1.0, -pi / 2), (1.0, -inf, pi), (-1.0, inf, -0.0),
    ]  # fmt: skip
    for p, q, want in special:
        got = trig.atan2_portable(p, q)
        assert got == want and math.copysign(1, got) == math.copysign(1, want), (p, q, got)
    assert math.isnan(trig.atan2_portable(math.nan, 1.0))


@pytest.mark.long
def test_bins_and_tallies_do_not_depend_on_the_cpu_dispatch(tmp_path):
    """The compiled bin pass, ``Bins.locate`` and the tallies of V-groove (exact, analytic,
    traced) and heightfield (traced through the facet table and per ray, all bounces, through
    a dielectric interface from both sides) runs are bitwise the same with NumPy's
    AVX-512 loops and numba's host target as with both held to AVX2 — and within each
    process the bin pass is ``Bins.locate``, ties on an edge included."""
    ran = dispatch_probe.prepared()  # by make test before its workers started
    proc = None
    if ran is None:  # the pinned process runs while this one computes its own
        inputs, out = dispatch_probe.write_inputs(tmp_path), tmp_path / "avx2.npz"
        proc = dispatch_probe.start(inputs, out, pinned=True)
    else:
        inputs, out = ran
    with np.load(inputs) as f:
        native = dispatch_probe.probe(dict(f))
    if proc is not None:
        stderr = proc.communicate(timeout=600)[1]
        assert proc.returncode == 0, stderr
    with np.load(out) as f:
        pinned = dict(f)
    # "haswell", not "haswell with the host's features": numba compiled Haswell's own code
    assert not pinned["numpy_avx512"] and str(pinned["numba_cpu"]) == "haswell"
    compared = [k for k in native if k not in ("numpy_avx512", "numba_cpu")]
    assert set(compared) <= set(pinned)
    differ = [k for k in compared if not np.array_equal(native[k], pinned[k], equal_nan=True)]
    assert not differ, f"differ across the dispatch paths: {differ}"
    with np.load(inputs) as f:
        single = f["status"] == paths.SINGLE
    for key in (k for k in compared if k.startswith("bin_rays-")):
        located = native[key.replace("bin_rays", "locate")]
        assert np.array_equal(native[key][single], located[single]), key
    assert native["vgroove-traced-counts"].sum() > 0 and native["file-bounces-counts"].sum() > 0
    assert native["file-per-ray-counts"].sum() > 0
    assert native["file-glass-btdf"].sum() > 0


def test_the_probed_kernels_are_compiled_once_each(tmp_path):
    """Every microsim kernel the dispatch probe runs (in a process of its own: the pinned
    probe of make test's warm-up, else one started here) gets one tuple of argument types, so
    a fresh cache compiles it once: a literal constant, a plain tuple for a NamedTuple or a
    writable array for a read-only one passed from compiled code would compile it again
    (``microsim.jit``)."""
    ran = dispatch_probe.prepared()
    if ran is None:
        inputs, out = dispatch_probe.write_inputs(tmp_path), tmp_path / "native.npz"
        proc = dispatch_probe.start(inputs, out, pinned=False)
        stderr = proc.communicate(timeout=600)[1]
        assert proc.returncode == 0, stderr
    else:
        out = ran[1]
    with np.load(out) as f:
        several = [str(name) for name in f["several_signatures"]]
    assert not several, f"compiled for more than one tuple of argument types: {several}"


def _specular_scenes():
    from microsim.app.scene import CATALOGUE, load_scene

    scenes = [load_scene(p) for p in sorted(CATALOGUE.glob("*.toml"))]
    return [sc for sc in scenes if sc.surface.kind == "flat" or sc.wave is not None]


def test_no_catalogue_specular_peak_sits_on_a_theta_edge():
    """Where a catalogue scene's reflection has a specular peak — a flat mirror, the
    diffraction orders of a wave scene — its direction (θo = θi, Δφ = 180°, a Δφ bin centre)
    lies at least a quarter bin from a θ edge for every incidence, so that no comparison of the
    peak depends on how a tie is broken (the rough scenes' lobes are continuous there)."""
    scenes = _specular_scenes()
    assert {sc.surface.kind for sc in scenes} >= {"flat", "abc"}
    for sc in scenes:
        width = 90.0 / sc.simulation.theta_bins
        for theta_i in sc.simulation.theta_i:
            if theta_i > 0.0:  # the zenith lies inside the first bin
                assert 0.25 <= (theta_i / width) % 1.0 <= 0.75, (sc.name, theta_i, width)


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def _jit_in(module: str):
    import numba

    def twice(x):
        return 2.0 * x

    twice.__module__ = module
    return numba.njit(twice)


def test_the_first_compilation_of_a_microsim_kernel_is_announced_once():
    """``compilation._FirstCompilation`` writes its one line at the first cache miss of a
    ``microsim`` kernel and never again; other packages' compilations say nothing;
    ``announce_compilation`` installs nothing for a stream that is not a terminal."""
    from numba.core import event

    from microsim.sim import compilation

    out = _Terminal()
    with event.install_listener("numba:compile", compilation._FirstCompilation(out)):
        _jit_in("elsewhere")(1.0)
        assert out.getvalue() == ""
        _jit_in("microsim.probe")(1.0)
        _jit_in("microsim.probe")(2.0)
    assert out.getvalue() == compilation.MESSAGE + "\n"
    before = list(compilation._INSTALLED)
    compilation.announce_compilation(io.StringIO())
    assert compilation._INSTALLED == before


def test_the_cli_announces_compilation_on_a_terminal_for_the_commands_that_compile(monkeypatch):
    """``microsim run``/``report``/``bench``/``sweep`` install the announcement on a terminal's
    stderr (before any kernel is needed); ``microsim models`` does not."""
    from numba.core import event

    from microsim.app import cli
    from microsim.sim import compilation

    for argv, installs in ((["models"], False), (["run", "no-such-scene.toml"], True)):
        terminal = _Terminal()
        monkeypatch.setattr(sys, "stderr", terminal)
        monkeypatch.setattr(compilation, "_INSTALLED", [])
        cli.main(argv)
        installed = list(compilation._INSTALLED)
        for listener in installed:
            event.unregister("numba:compile", listener)
        assert [x.stream for x in installed] == ([terminal] if installs else [])


_CACHE_PROBE = """
import sys, zlib
import numpy as np
from numba.core import event
compiled = []
class Count(event.Listener):
    def on_start(self, ev):
        compiled.append(ev.data["dispatcher"].py_func.__name__)
    def on_end(self, ev):
        pass
event.register("numba:compile", Count())
from microsim.sim import Bins
wo = np.random.default_rng(1).normal(size=(1000, 3))
theta, phi = Bins.angles(wo / np.linalg.norm(wo, axis=1)[:, None])
print(len(compiled), zlib.crc32(theta.tobytes() + phi.tobytes()))
"""


def test_the_kernel_cache_is_keyed_by_cpu_and_safe_for_concurrent_first_starts(tmp_path):
    """On an empty cache (``NUMBA_CACHE_DIR``) two processes starting at once both compile
    and agree; a third loads from the cache (compiles nothing); one targeting another CPU
    (Haswell) compiles anew rather than loading the host's machine code, and agrees too."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    for key in dispatch_probe.AVX2_ENV:
        env.pop(key, None)
    cmd = [sys.executable, "-c", _CACHE_PROBE]
    run = lambda e: subprocess.Popen(cmd, env=e, stdout=subprocess.PIPE, text=True)  # noqa: E731
    first = [run(env), run(env)]
    outs = [p.communicate(timeout=300)[0].split() for p in first]
    assert all(p.returncode == 0 for p in first)
    warm = run(env).communicate(timeout=300)[0].split()
    other = run({**env, **dispatch_probe.AVX2_ENV}).communicate(timeout=300)[0].split()
    assert int(outs[0][0]) > 0 and int(outs[1][0]) > 0
    assert int(warm[0]) == 0 and int(other[0]) > 0
    assert outs[0][1] == outs[1][1] == warm[1] == other[1]


_OLD_MODULE = """
from typing import NamedTuple
from microsim.kernel_cache import cached_njit

@cached_njit()
def total(p):
    return p[0] + p[1]

class Pair(NamedTuple):
    a: float
    b: float

print(total(Pair(1.0, 2.0)))
"""

_NEW_MODULE = """
from microsim.kernel_cache import cached_njit


@cached_njit()
def total(p):
    return p[0] + p[1]

print(total((1.0, 2.0)))
"""  # ``total`` on the same line: the same cache index file


def test_a_kernel_cache_left_by_another_version_is_recompiled_not_fatal(tmp_path):
    """A kernel cached by a version of its module whose signature named a type since removed
    (an upgrade, or a checkout of an older commit, keeps the cache folder): numba would fail
    to unpickle the index on every call; the kernel compiles anew and runs instead."""
    module = tmp_path / "kernels_then.py"
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache"), "PYTHONPATH": str(tmp_path)}
    cmd = [sys.executable, "-c", "import kernels_then"]  # imported: its types by reference
    for text in (_OLD_MODULE, _NEW_MODULE):
        module.write_text(text)
        done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
        assert done.returncode == 0 and done.stdout.split() == ["3.0"], done.stderr


def test_a_cached_kernel_is_checked_against_every_module_of_the_package():
    """numba checks a cached kernel against its own file only; the kernels also carry the
    package's stamp, so an edit of a helper they inline (another module) recompiles them."""
    from microsim import kernel_cache
    from microsim.sim import vgroove_kernels

    kernel = vgroove_kernels.analytic_vgroove_bounces
    stamp = kernel._cache._cache_file._source_stamp
    assert stamp[1] == kernel_cache.PACKAGE_STAMP
    assert len(kernel_cache.PACKAGE_STAMP) == 64

"""`microsim bench --methods`: wall time against error for the methods themselves — which
method a scene needs, and what it costs.

Two scenes, each judged against its own reference; every time is wall seconds on this machine
(``time.perf_counter``), the best of ``repeat`` (3) runs where one run takes less than
``cheap`` seconds, else one run; ``threads`` (2) worker threads / FFT workers throughout. What
is timed is the method's own work for one incidence: the closed forms' bin averages over the
bins, ``simulate`` (surface, Embree scene and BVH, and for the analytic V-groove path the numba
compilation excluded: a warm-up call on the same surface object does them, and its time is
recorded as ``setup_seconds``), ``kirchhoff_brdf`` (surface synthesis excluded).

Panel A, geometric scene: V-grooves with a Beckmann NDF, m = 0.3 (``surfaces.vgrooves(4000,
Beckmann(0.3), seed=0)``), aluminium, θi = 30°, ``Bins(45, 37)`` (2° × 5° folded, the bins of
``microsim bench``'s throughput runs: with the 2° × 2° bins of its time-to-accuracy run, 10⁴
rays leave no bin with the 25 events a verdict needs). Reference: the exact closed form of that
surface, Torrance–Sparrow with the V-groove G (Mikkelsen 2009, eq. 25), bin-averaged by
``sim.predict.predict`` to relative quadrature error 1e-6. Error: the energy-weighted relative
RMS error over the bins carrying 90 % of the energy,
``analysis.verdicts.verdict(...)["rel_rms"]``, √(Σ_E f̄Ω ((m − f̄)/f̄)²/Σ_E f̄Ω), with f̄ the
method's bins and m the reference's for the ray traces (so it *includes the ray noise*: it
falls as 1/√N until the model-error floor — here the finite sample of 4000 grooves against the
nominal NDF), and f̄ the reference, m the closed form for the closed forms. Methods:
Torrance–Sparrow with Smith G (a real model error on V-grooves) and with the V-groove G at the
project's default quadrature tolerance 1e-3 (its error is that quadrature error); the ray trace
(``simulate``, ``masking="traced"``: Embree) and the exact V-groove path
(``masking="analytic"``: float64, no Embree) at increasing ray counts. A ray-trace point's
error is the mean over the repeated runs (seeds 0, 1, 2), its uncertainty the standard
deviation of those errors / √runs (None after a single run), and ``noise_floor`` = √(Σ_E f̄Ω
(se/f̄)²/Σ_E f̄Ω) the part the ray noise alone contributes.

Panel B, wave scene: the catalogue scene abc-transition-wave (ABC PSD, σ = 0.125
µm = λ/4, B = 10 µm, C = 2.5, band limit 4, exact amplitudes, dx = 0.1 µm = λ/5, λ = 0.5 µm;
the transition regime), aluminium, θi = 30°, ``Bins(18, 13)`` (5° × 15° folded). Reference:
the Kirchhoff solver (``wave.kirchhoff_brdf``, the smooth interpolant upsampled 2×, as the
scene) on the largest tile afforded: ``wave_ref_n``² = 1024² samples, 102.4 µm = 204.8 λ
(``--quick``: 256², 51.2 λ). Error: |energy deviation| over the reference's 90 % diffuse
energy set, ``analysis.wave_verdicts.wave_verdict(...)["energy_dev"]`` = Σ_E Ω(f̄ − m)/Σ_E Ω f̄
(f̄ the reference's diffuse part, m the method's bins; bins beyond θo = 80° left out), the
measure of the regime map. Its uncertainty combines in quadrature the reference's speckle
part (``energy_dev_se``, common to every point of the panel; the reference's own relative
speckle error of its energy Σ_E Ω f̄ is the panel's ``reference_se``, drawn as a dotted line)
and the method's own noise, √(Σ_E (Ω se_m)²)/Σ_E Ω f̄ (ray noise; a smaller Kirchhoff tile's own
speckle). Methods: Kirchhoff on smaller tiles (``wave_tiles``: 64²–512² at the same dx, new
realisations of the same PSD: the error includes realisation scatter), Rayleigh–Rice (Löw et
al. 2012, eq. 3, nominal PSD, no fit), Löw's smooth-surface model (PSD's A, B, C), the
first-order Kirchhoff expression, Torrance–Sparrow with Smith G and Beckmann(m realised by the
reference tile), all four bin-averaged by ``sim.predict.bin_average`` (rtol 1e-3; the error
with the solver's own lattice averaging is kept as ``error_lattice``), and the ray trace of
the reference tile itself at increasing ray counts — its error stops falling at the
geometric-optics error of this σ/λ: more rays do not buy accuracy a wave scene needs.

Panel C, full-wave rung (only with the `fullwave` extra; without it the study's
``fullwave_skipped`` says why): a periodic Gaussian glass profile from the full-wave map
(``wave.random_profiles``: ℓ = λ, nominal rms slope ``grating_slope``, Λ = 4 ℓ, 32 samples,
seed 0), θi as above. Reference: RCW (``wave.fullwave.converged_efficiencies``, tolerance
10⁻³). Error: the share of the reflected power put in the wrong orders, Σ|η − η_RCW|/Σ η_RCW
over the orders with θo ≤ 80° (``analysis.fullwave_map.order_error``). Methods: RCW at each
truncation of its convergence study (its error against the converged solution; the converged
point's own error is its last change under a raise, the truncation it can vouch for), and
scalar Kirchhoff (``wave.gratings.kirchhoff_efficiencies``) against it.

Output (``methods_study``): a JSON-able dict — ``machine`` (cpus, load average at start and
end, threads, git commit when the package is a checkout and whether its microsim/ had
uncommitted changes), ``settings``, ``panels`` (each:
``key``, ``title``, ``scene``, ``reference``, ``error_measure``, ``points``: {method, kind
"closed-form" | "curve", setting, size, seconds, runs, error, error_se, ...}). Errors are
dimensionless fractions, times seconds.
"""

from __future__ import annotations

from pathlib import Path

from .bench_methods_chart import MethodsStudy, format_methods, methods_chart
from .bench_methods_study import QUICK, MethodsConfig, methods_config, methods_study

__all__ = [
    "MethodsConfig",
    "MethodsStudy",
    "QUICK",
    "methods_config",
    "methods_study",
    "methods_chart",
    "format_methods",
    "write_methods",
    "run_methods_command",
    "METHODS_JSON",
    "METHODS_PNG",
]

METHODS_JSON = "methods.json"
METHODS_PNG = "methods.png"


def write_methods(study: dict, out) -> tuple[Path, Path]:
    """Write ``out/methods.json`` and ``out/methods.png``, each atomically (``atomic``)."""
    from ..atomic import write_json

    out = Path(out)
    if out.exists() and not out.is_dir():
        from ..errors import UsageError

        raise UsageError(f"--methods {out}: exists and is not a directory")
    png, js = out / METHODS_PNG, out / METHODS_JSON
    methods_chart(study, png)
    write_json(js, study)
    return js, png


def run_methods_command(args) -> int:
    """``microsim bench --methods [DIR] [--quick] [--json]``: the study, written to
    DIR/methods.json and DIR/methods.png (nothing written if it fails), the table (or the JSON
    with ``--json``) printed. ``--rays`` and ``--skip-accuracy`` belong to the throughput bench
    and are refused here."""
    import json

    from ..errors import UsageError

    if getattr(args, "rays", None) is not None or getattr(args, "skip_accuracy", False):
        raise UsageError(
            "--methods: --rays and --skip-accuracy apply to the throughput bench only; "
            "allowed with --methods: --quick, --json"
        )
    out = Path(args.methods)
    if out.exists() and not out.is_dir():
        raise UsageError(f"--methods {out}: exists and is not a directory")
    study = methods_study(quick=bool(args.quick))
    js, png = write_methods(study, out)
    print(json.dumps(study, indent=1) if args.json else format_methods(study))
    print(f"microsim: wrote {js} and {png}")
    return 0

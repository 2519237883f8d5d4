"""The figures of ``microsim bench`` as frozen records, their JSON form and their text.

``bench.run_bench`` returns a ``Bench``; ``Bench.to_json`` is what ``bench --json`` prints
(per-thread figures keyed by the thread count, which JSON writes as "1" and "2"), and
``Bench.from_json`` reads that back (the one loader: string thread keys become integers again,
sections a run skipped stay None). ``format_bench`` is the table ``bench`` prints.
"""

from __future__ import annotations

import statistics
from dataclasses import dataclass, fields, is_dataclass, replace

from .wave_bench import WaveTiming

__all__ = [
    "Accuracy",
    "AzimuthCost",
    "GGXSurfaceCost",
    "InterfaceLine",
    "InterfaceThroughput",
    "Bench",
    "BenchConfig",
    "BounceThroughput",
    "BuildTimes",
    "FixedCost",
    "FoldedFull",
    "Machine",
    "Marginal",
    "MarginalLine",
    "PeerSetup",
    "RawThroughput",
    "RoundRatios",
    "format_bench",
]


@dataclass(frozen=True)
class BenchConfig:
    """What is measured: heightfield ``n``² (dx = 1, σ, ℓ), ``rays`` primary rays at
    ``theta_i`` degrees; memory probed at ``memory_rays`` (two counts); time to ``target``
    relative error on the V-groove scene with ``vgrooves`` grooves (``skip_accuracy`` omits it);
    the wave solver on a ``wave_n``² tile of ``wave_tile`` wavelengths (``skip_wave`` omits it)."""

    n: int = 512
    sigma: float = 1.2
    corr_len: float = 8.0
    theta_i: float = 30.0
    rays: int = 2**22
    memory_rays: tuple = (2**20, 2**23)  # both above the mesh's facet count
    target: float = 0.01
    vgrooves: int = 4000
    max_rays: int = 10**8
    skip_accuracy: bool = False
    wave_n: int = 1024
    wave_tile: float = 200.0
    skip_wave: bool = False


THREADS = (1, 2)
"""The thread counts every per-thread figure is measured on."""


def to_json(value):
    """``value`` with every record replaced by its JSON object (fields in declaration order,
    or the record's own ``to_json``), dicts and lists walked."""
    if hasattr(value, "to_json"):
        return value.to_json()
    if is_dataclass(value):
        return {f.name: to_json(getattr(value, f.name)) for f in fields(value)}
    if isinstance(value, dict):
        return {k: to_json(v) for k, v in value.items()}
    if isinstance(value, list):
        return [to_json(v) for v in value]
    return value


def per_thread(figures: dict | None, read=lambda v: v) -> dict | None:
    """{1: .., 2: ..} from a per-thread figure as saved (string keys) or in memory, each value
    through ``read``; None stays None."""
    return None if figures is None else {int(t): read(v) for t, v in figures.items()}


def _record(cls, doc: dict | None):
    """``cls`` from its JSON object (absent fields take their defaults); None stays None."""
    return (
        None if doc is None else cls(**{f.name: doc[f.name] for f in fields(cls) if f.name in doc})
    )


@dataclass(frozen=True)
class Machine:
    """What the figures were measured on (``bench.machine``) and how the heightfield grid walk
    ran there (``grid_walk``: "16 rays side by side" or "one ray at a time",
    ``heightfield_caster.LANE_WALK``; records without it were walked one ray at a time)."""

    cpu: str
    isa: str
    numpy_dispatch: list
    numba_cpu: str
    grid_walk: str = "one ray at a time"


@dataclass(frozen=True)
class PeerSetup:
    """The Mitsuba 3 peer the throughput was compared with: its variant and version, the tile
    copies per side of its scene, the seconds its build took and the LLVM target its kernels
    were compiled for ({"cpu", "lanes"}, ``bench_peer.llvm_target``)."""

    variant: str
    mitsuba_version: str
    copies: int
    build_seconds: float
    llvm_target: dict | None = None

    def target_text(self) -> str:
        """ ", kernels for znver4, 16 lanes" from the recorded LLVM target, if any."""
        t = self.llvm_target
        if not t:
            return ""
        cpu, lanes = t.get("cpu"), t.get("lanes")
        return f", kernels for {cpu}" + (f", {lanes} lanes" if lanes else "")


@dataclass(frozen=True)
class RawThroughput:
    """Raw Embree figures for the pipeline's own rays (``bench.throughput``): ray counts,
    rays/s and samples/s per thread count, the packet binding's rays/s and width (None with
    the reason when unavailable) and the Mitsuba peer's samples/s and set-up (likewise)."""

    primary_rays: int
    masking_rays: int
    rays_per_s: dict
    samples_per_s: dict
    rays: int | None = None
    packet_rays_per_s: dict | None = None
    packet_width: int | None = None
    packets_unavailable: str | None = None
    peer_samples_per_s: dict | None = None
    peer: PeerSetup | None = None
    peer_unavailable: str | None = None

    def to_json(self) -> dict:
        order = ("rays", "primary_rays", "masking_rays", "rays_per_s", "samples_per_s")
        rest = [f.name for f in fields(self) if f.name not in order]
        return {name: to_json(getattr(self, name)) for name in (*order, *rest)}

    @classmethod
    def from_json(cls, doc: dict) -> RawThroughput:
        raw = _record(cls, doc)
        return replace(
            raw,
            rays_per_s=per_thread(raw.rays_per_s),
            samples_per_s=per_thread(raw.samples_per_s),
            packet_rays_per_s=per_thread(raw.packet_rays_per_s),
            peer_samples_per_s=per_thread(raw.peer_samples_per_s),
            peer=_record(PeerSetup, raw.peer),
        )


@dataclass(frozen=True)
class MarginalLine:
    """The line through a caller's best wall times at two ray counts: its slope
    ``samples_per_s`` and intercept ``fixed_seconds`` (both None when the larger call was no
    slower), and the two ``seconds``."""

    samples_per_s: float | None
    fixed_seconds: float | None
    seconds: list

    @classmethod
    def through(cls, times: dict) -> MarginalLine:
        """The line through {rays: best seconds} of two ray counts."""
        (n1, t1), (n2, t2) = sorted(times.items())
        if not t2 > t1:  # the larger call no faster: too few rays to resolve the margin
            return cls(None, None, [t1, t2])
        rate = (n2 - n1) / (t2 - t1)
        return cls(rate, t1 - n1 / rate, [t1, t2])

    def resolved(self) -> bool:
        return self.samples_per_s is not None


@dataclass(frozen=True)
class RoundRatios:
    """The pipeline / peer ratio of the marginal rates within each round of
    ``bench.marginal_throughput`` (its four calls, one after the other, see the same turn of a
    shared host): ``median``, ``low`` and ``high`` over the ``rounds`` whose two margins were
    resolved — the ratio's spread, where the best-of ratio gives one figure."""

    median: float
    low: float
    high: float
    rounds: int

    @classmethod
    def of(cls, rays: list, pipeline: dict, peer: dict) -> RoundRatios | None:
        """From {rays: [seconds of each round]} of the two sides (the same rounds, in order);
        a round counts where both sides' larger call was the slower; None if none did."""
        n1, n2 = sorted(rays)
        ratios = [
            (q2 - q1) / (p2 - p1)  # (n2 − n1)/(p2 − p1) over (n2 − n1)/(q2 − q1)
            for p1, p2, q1, q2 in zip(pipeline[n1], pipeline[n2], peer[n1], peer[n2])
            if p2 > p1 and q2 > q1
        ]
        if not ratios:
            return None
        return cls(statistics.median(ratios), min(ratios), max(ratios), len(ratios))


@dataclass(frozen=True)
class Marginal:
    """``bench.marginal_throughput``: the two ray counts, the pipeline's and the peer's lines
    per thread count (the peer's None, with the reason, when it did not run), the ratio of
    their rates (None where either is unresolved) and, per thread count, that ratio round by
    round (``RoundRatios``; None without the peer or in records written before it)."""

    rays: list
    pipeline: dict
    peer: dict | None
    peer_unavailable: str | None
    ratio: dict | None
    ratio_rounds: dict | None = None

    @classmethod
    def of(cls, rays: list, pipeline: dict, peer: dict | None, reason) -> Marginal:
        """The record of the two callers' wall times per thread count, {rays: [seconds of
        each round]} (``peer`` None: it did not run, ``reason``): the line through each side's
        best times (``MarginalLine.through``), the ratio of their rates and its rounds."""

        def lines(times: dict) -> dict:
            return {
                t: MarginalLine.through({n: min(s) for n, s in times[t].items()}) for t in THREADS
            }

        ours = lines(pipeline)
        if peer is None:
            return cls(rays, ours, None, reason, None)
        theirs = lines(peer)
        ratio = {
            t: ours[t].samples_per_s / theirs[t].samples_per_s
            if ours[t].resolved() and theirs[t].resolved()
            else None
            for t in THREADS
        }
        rounds = {t: RoundRatios.of(rays, pipeline[t], peer[t]) for t in THREADS}
        return cls(rays, ours, theirs, reason, ratio, rounds)

    @classmethod
    def from_json(cls, doc: dict) -> Marginal:
        def lines(d):
            return per_thread(d, lambda v: _record(MarginalLine, v))

        mg = _record(cls, doc)
        return replace(
            mg,
            pipeline=lines(mg.pipeline),
            peer=lines(mg.peer),
            ratio=per_thread(mg.ratio),
            ratio_rounds=per_thread(mg.ratio_rounds, lambda v: _record(RoundRatios, v)),
        )


@dataclass(frozen=True)
class InterfaceLine:
    """One incidence of ``bench.interface_throughput``: θi in degrees ((90, 180]: from inside
    the medium), the ``Marginal`` of the pipeline's and the peer's paths/s (a path = a primary
    ray and every ray that continues it) and the rays the peer traced per path (None without
    the peer)."""

    theta_i: float
    marginal: Marginal
    rays_per_path: float | None = None

    @classmethod
    def from_json(cls, doc: dict) -> InterfaceLine:
        return replace(_record(cls, doc), marginal=Marginal.from_json(doc["marginal"]))


@dataclass(frozen=True)
class InterfaceThroughput:
    """``bench.interface_throughput``: the dielectric path (``simulate(..., transmission=True,
    bounces=...)``) of a medium of index ``eta`` against the Mitsuba peer's
    (``bench_peer.PeerScene.run_dielectric``), one ``InterfaceLine`` per incidence."""

    eta: float
    bounces: str
    incidences: list

    @classmethod
    def from_json(cls, doc: dict) -> InterfaceThroughput:
        lines = [InterfaceLine.from_json(d) for d in doc["incidences"]]
        return cls(doc["eta"], doc["bounces"], lines)


@dataclass(frozen=True)
class BuildTimes:
    """Seconds to build the Embree scene + BVH with embreex and with the packet binding (None,
    with the reason, when unavailable)."""

    embreex: float
    packets: float | None
    packets_unavailable: str | None = None


@dataclass(frozen=True)
class FixedCost:
    """Seconds of a one-block ``simulate`` call: the first on a surface and one reusing its
    tracer."""

    first_call: float
    reused: float


@dataclass(frozen=True)
class FoldedFull:
    """One figure on folded bins and on full-azimuth bins."""

    folded: float
    full: float


@dataclass(frozen=True)
class AzimuthCost:
    """``bench.azimuth_cost``: pipeline samples/s and one model's bin-average seconds, folded
    against full-azimuth bins."""

    samples_per_s: FoldedFull
    predict_seconds: FoldedFull

    @classmethod
    def from_json(cls, doc: dict) -> AzimuthCost:
        return cls(**{name: FoldedFull(**figures) for name, figures in doc.items()})


@dataclass(frozen=True)
class GGXSurfaceCost:
    """``bench.ggx_surface_cost``: pipeline samples/s per thread count on the Gaussian bench
    surface and on the GGX heightfield of the same grid."""

    gaussian: dict
    ggx: dict

    @classmethod
    def from_json(cls, doc: dict) -> GGXSurfaceCost:
        return cls(**{name: per_thread(figures) for name, figures in doc.items()})


@dataclass(frozen=True)
class BounceThroughput:
    """Pipeline samples/s per thread count with ``bounces=1`` (``one``) and ``bounces="all"``
    (``every``); saved as {"1": .., "all": ..}."""

    one: dict
    every: dict

    _SAVED_AS = {"one": "1", "every": "all"}

    def to_json(self) -> dict:
        return {key: getattr(self, name) for name, key in self._SAVED_AS.items()}

    @classmethod
    def from_json(cls, doc: dict) -> BounceThroughput:
        return cls(**{name: per_thread(doc.get(key)) for name, key in cls._SAVED_AS.items()})


@dataclass(frozen=True)
class Accuracy:
    """``bench.time_to_accuracy``: seconds, rays and rays/s to the target error with one
    masking path, the relative standard error reached (converged or not), the relative RMS
    error against the closed form and its χ²/dof, on ``threads`` threads."""

    seconds: float
    rays: int
    rays_per_s: float
    masking: str
    rse: float
    converged: bool
    rel_rms_vs_closed_form: float
    chi2_dof: float
    threads: int


@dataclass(frozen=True)
class Bench:
    """Every figure of ``microsim bench`` (``bench.run_bench``); a section the run skipped (or
    a partial record's missing section) is None."""

    config: BenchConfig
    load_average: list
    cpus: int
    mesh_triangles: int
    raw: RawThroughput
    pipeline_samples_per_s: dict
    ratio: dict
    peak_rss_mb: dict
    machine: Machine | None = None
    marginal: Marginal | None = None
    build_seconds: BuildTimes | None = None
    fixed_cost: FixedCost | None = None
    bounces: BounceThroughput | None = None
    full_azimuth: AzimuthCost | None = None
    ggx_surface: GGXSurfaceCost | None = None
    dielectric: InterfaceThroughput | None = None
    time_to_accuracy: Accuracy | None = None
    time_to_accuracy_traced: Accuracy | None = None
    wave: list | None = None

    _ORDER = (
        "config",
        "machine",
        "load_average",
        "cpus",
        "mesh_triangles",
        "raw",
        "pipeline_samples_per_s",
        "ratio",
        "marginal",
        "build_seconds",
        "fixed_cost",
        "bounces",
        "full_azimuth",
        "ggx_surface",
        "dielectric",
        "peak_rss_mb",
        "time_to_accuracy",
        "time_to_accuracy_traced",
        "wave",
    )

    def to_json(self) -> dict:
        """The JSON object ``bench --json`` prints (skipped sections left out)."""
        doc = {name: to_json(getattr(self, name)) for name in self._ORDER}
        return {k: v for k, v in doc.items() if v is not None}

    @classmethod
    def from_json(cls, doc: dict) -> Bench:
        """The record of a saved ``bench --json`` object."""
        readers = {
            "config": _config,
            "raw": RawThroughput.from_json,
            "pipeline_samples_per_s": per_thread,
            "ratio": per_thread,
            "peak_rss_mb": lambda d: {int(rays): mb for rays, mb in d.items()},
            "machine": lambda d: Machine(**d),
            "marginal": Marginal.from_json,
            "build_seconds": lambda d: BuildTimes(**d),
            "fixed_cost": lambda d: FixedCost(**d),
            "bounces": BounceThroughput.from_json,
            "full_azimuth": AzimuthCost.from_json,
            "ggx_surface": GGXSurfaceCost.from_json,
            "dielectric": InterfaceThroughput.from_json,
            "time_to_accuracy": lambda d: Accuracy(**d),
            "time_to_accuracy_traced": lambda d: Accuracy(**d),
            "wave": _wave_rows,
        }
        return cls(
            **{
                name: readers.get(name, _same)(value)
                for name, value in doc.items()
                if value is not None
            }
        )


def _same(value):
    return value


def _config(doc: dict) -> BenchConfig:
    """The ``BenchConfig`` of a saved bench (its memory probe counts a tuple again)."""
    memory = doc.get("memory_rays")
    return BenchConfig(**{**doc, **({} if memory is None else {"memory_rays": tuple(memory)})})


def _wave_rows(rows: list) -> list:
    return [WaveTiming(**r) for r in rows]


def _row(label: str, figures: dict, fmt: str = "14.4g") -> str:
    """A table row: the label, then the 1- and 2-thread figures."""
    return f"{label:28s}" + "".join(f"{figures[t]:{fmt}}" for t in THREADS)


def format_bench(b: Bench) -> str:
    """Human-readable table of ``run_bench`` output."""
    lines = [] if b.machine is None else [_machine_line(b.machine)]
    lines += _throughput_lines(b)
    lines += _marginal_lines(b.marginal)
    lines += _interface_lines(b.dielectric)
    lines += _cost_lines(b)
    lines += [f"peak RSS, {r} rays: {mb:.0f} MB" for r, mb in b.peak_rss_mb.items()]
    for t in (b.time_to_accuracy, b.time_to_accuracy_traced):
        if t:
            lines.append(_accuracy_line(t, b.config.target))
    lines += [_wave_line(w) for w in b.wave or []]
    return "\n".join(lines)


def _machine_line(m: Machine) -> str:
    return (
        f"machine: {m.cpu}, {m.isa} (NumPy dispatch "
        f"{', '.join(m.numpy_dispatch) or 'baseline'}; numba target {m.numba_cpu}; "
        f"grid walk {m.grid_walk})"
    )


def _throughput_lines(b: Bench) -> list[str]:
    """The whole-run rows: raw embreex, packets, the pipeline and the Mitsuba peer."""
    raw, pipe = b.raw, b.pipeline_samples_per_s
    lines = [
        f"mesh: {b.mesh_triangles} triangles; {raw.primary_rays} primary + "
        f"{raw.masking_rays} masking rays; load average {b.load_average[0]:.2f} "
        f"on {b.cpus} CPUs",
        f"{'':28s}{'1 thread':>14s}{'2 threads':>14s}",
        _row("raw embreex rays/s", raw.rays_per_s),
        _row("raw embreex samples/s", raw.samples_per_s),
    ]
    pk = raw.packet_rays_per_s
    if pk:
        lines += [
            _row(f"raw packets ({raw.packet_width} lanes) rays/s", pk),
            _row("packets / embreex", {t: pk[t] / raw.rays_per_s[t] for t in THREADS}, "14.2f"),
        ]
    else:
        lines.append(f"packets unavailable: {raw.packets_unavailable}")
    lines += [_row("pipeline samples/s", pipe), _row("pipeline / raw", b.ratio, "14.1%")]
    pr = raw.peer_samples_per_s
    if pr:
        p = raw.peer
        lines += [
            _row("Mitsuba 3 peer samples/s", pr),
            _row("pipeline / Mitsuba peer", {t: pipe[t] / pr[t] for t in THREADS}, "14.2f")
            + "   (whole runs: each side's fixed cost included)",
            f"  (mitsuba {p.mitsuba_version} {p.variant}{p.target_text()}, "
            f"{p.copies}×{p.copies} tile copies, not robust; scene build "
            f"{p.build_seconds:.1f} s excluded)",
        ]
    elif raw.peer_unavailable:
        lines.append(f"Mitsuba 3 peer skipped: {raw.peer_unavailable}")
    return lines


def _marginal_lines(mg: Marginal | None, title: str = "", per: str = "rays") -> list[str]:
    """``format_bench``'s lines for ``marginal_throughput``'s figures (none without them):
    ``title`` before the two call sizes, counted in ``per`` ("rays": rates in samples/s; or
    "paths": paths/s)."""
    if not mg:
        return []
    n1, n2 = mg.rays

    def row(label, fig) -> str:
        if not all(fig[t].resolved() for t in THREADS):
            return f"{label:28s}not resolved at these ray counts (the larger call was no slower)"
        return (
            _row(label, {t: fig[t].samples_per_s for t in THREADS})
            + f"   (fixed per call {fig[1].fixed_seconds:.3f}, {fig[2].fixed_seconds:.3f} s)"
        )

    unit = "samples/s" if per == "rays" else f"{per}/s"
    lines = [f"{title}marginal, {n1:,} → {n2:,} {per}:", row(f"  pipeline {unit}", mg.pipeline)]
    if mg.peer:
        lines.append(row(f"  Mitsuba peer {unit}", mg.peer))
        if None not in mg.ratio.values():
            lines.append(_row("  pipeline / Mitsuba peer", mg.ratio, "14.2f"))
        rounds = mg.ratio_rounds
        if rounds and None not in rounds.values():
            ranges = ", ".join(f"{rounds[t].low:.2f}–{rounds[t].high:.2f}" for t in THREADS)
            n = sorted({rounds[t].rounds for t in THREADS})
            lines.append(
                _row("  the same, round by round", {t: rounds[t].median for t in THREADS}, "14.2f")
                + f"   (ranges {ranges}; medians of {' and '.join(map(str, n))} rounds)"
            )
    return lines


def _interface_lines(di: InterfaceThroughput | None) -> list[str]:
    """``format_bench``'s lines for the dielectric path against its peer, per incidence."""
    if not di:
        return []
    lines = []
    for line in di.incidences:
        side = "from inside the medium" if line.theta_i > 90.0 else "from the air"
        title = f"dielectric path θi = {line.theta_i:g}° ({side}, η = {di.eta:g}), "
        lines += _marginal_lines(line.marginal, title, "paths")
        if line.rays_per_path is not None:
            lines.append(
                f"  (bounces={di.bounces}; the peer traced {line.rays_per_path:.3f} rays/path)"
            )
    return lines


def _cost_lines(b: Bench) -> list[str]:
    """Every bounce, full-azimuth bins, the fixed cost of a call and the scene build."""
    lines = []
    if b.bounces:
        one = b.bounces.one
        lines.append(
            _row("pipeline, all bounces", b.bounces.every)
            + f"   (bounces=1 in the same runs: {one[1]:.4g}, {one[2]:.4g})"
        )
    if b.full_azimuth:
        r, t = b.full_azimuth.samples_per_s, b.full_azimuth.predict_seconds
        lines.append(
            f"full-azimuth bins (72 × 5°) vs folded (37 × 5°), 2 threads: pipeline "
            f"{r.full:.4g} vs {r.folded:.4g} samples/s; one model's bin averages "
            f"{t.full:.2f} s (anisotropic, full) vs {t.folded:.2f} s (isotropic, folded)"
        )
    if b.ggx_surface:
        lines.append(
            _row("pipeline, GGX heightfield", b.ggx_surface.ggx)
            + "   (same grid; Gaussian in the same runs: "
            + ", ".join(f"{b.ggx_surface.gaussian[t]:.4g}" for t in THREADS)
            + ")"
        )
    if b.fixed_cost:
        lines.append(
            f"simulate fixed cost (one block of rays): first call "
            f"{b.fixed_cost.first_call:.3f} s, tracer reused {b.fixed_cost.reused:.3f} s"
        )
    bt = b.build_seconds
    if bt:
        pk_s = "unavailable" if bt.packets is None else f"{bt.packets:.3f} s"
        lines.append(f"scene + BVH build: embreex {bt.embreex:.3f} s, packets {pk_s}")
    return lines


def _accuracy_line(t: Accuracy, target: float) -> str:
    return (
        f"time to {target:.0%} (V-groove Beckmann 0.3, Al, 30°, 2° bins, "
        f"masking={t.masking}, {t.threads} threads): {t.seconds:.2f} s, "
        f"{t.rays} rays ({t.rays_per_s:.3g} rays/s), rse "
        f"{t.rse:.4f}, rel. RMS vs closed form {t.rel_rms_vs_closed_form:.4f}"
        f" (χ²/dof {t.chi2_dof:.3f})"
    )


def _wave_line(w) -> str:
    return (
        f"wave solver (Kirchhoff, {w.surface}), {w.n}² tile of {w.tile:g} λ, "
        f"σ = {w.sigma:g} λ, θi = {w.theta_i:g}°: {w.seconds:.2f} s for one "
        f"incidence, {w.orders} orders, {w.qz_nodes} q_z nodes, upsample "
        f"{w.upsample}, order power {w.albedo:.4f}"
    )

"""Running sums of the traced rays, the bin estimate with its standard error, and the Result.

Each ray r contributes x_r = w_r·1[r in B] to bin B, w_r its Fresnel weight (``paths``). The
bin average of the explicit microfacet integral (Mikkelsen 2009, eq. 9) over N primary rays is

    f̄_B = Σ_r x_r / (N Ω_B),      Ω_B = bin projected solid angle (sr, ``Bins``),

in sr⁻¹. Its standard error (``bin_estimate``) comes from paired strata: rays 2k and 2k + 1
are two independent uniform samples of one stratum [2k/N, (2k + 2)/N) of the tile
(``streams.chunk_origins``), so (x_2k − x_2k+1)²/2 is an unbiased estimate of that stratum's
variance and

    se_B = √(Σx² − 2 Σ_k x_2k x_2k+1) / (N Ω_B)

estimates the variance of f̄_B without bias (Cochran, Sampling Techniques, 3rd ed., §5.5),
where Σ_k x_2k x_2k+1 is the tally ``sum_pair``. The per-ray (i.i.d.) formula
√((Σx²/N − (Σx/N)²)/(N − 1)) / Ω_B ignores the stratification and overestimates the error
(≈ 2.2× in σ on a 128² Gaussian heightfield with 2·10⁵ rays — tests/test_stderr.py); it is
kept for independent origins and for ``isotropic`` runs.

Sums are kept per block (``split_tallies``) and added in block order (``Tally.add_chunk``), so
they are bitwise the same for any chunking or thread count, and exact enough to resume from
(``tally_arrays``/``tallies_from_arrays``, stored as ``Result.tallies``). The ledger
(``paths.LEDGER``) is tallied alongside: ``single_fresnel`` is the measured single-bounce
albedo ρ(θi) (Mikkelsen 2009, eq. 27); ``lost``/``lost_fresnel`` are the unweighted and
Fresnel-weighted fractions single scattering loses (masked + downward).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from microsim.bins import Bins
from microsim.stats import MIN_EVENTS

from . import tally_kernels
from .ledger import (
    DIELECTRIC_COLUMNS,
    DIELECTRIC_TERMINAL,
    DOWNWARD,
    LEDGER,
    MASKED,
    TERMINAL,
    TIR_ORDERS,
)
from .result import Result
from .scratch import WorkArray
from .streams import BLOCK

__all__ = [
    "Tally",
    "ChunkTallies",
    "split_tallies",
    "chunk_tallies",
    "bin_estimate",
    "tally_result",
    "simulation_result",
    "tally_arrays",
    "tallies_from_arrays",
    "TALLY_NAMES",
    "STDERR_METHODS",
    "PairSums",
    "BlockSums",
    "block_sizes",
    "stderr_dof",
    "pair_error_trusted",
    "MIN_DISCORDANT",
    "STDERR_RULE",
    "terminal_ledger",
    "split_order_tallies",
    "chunk_order_tallies",
    "chunk_sums",
    "chunk_of",
    "ledger_columns",
]

TALLY_NAMES = (
    "sum_w",
    "sum_w2",
    "count",
    "led_n",
    "led_f",
    "sum_pair",
    "sum_block2",
    "sum_block_rays",
)
"""The running sums of a ``Tally``, in its field order (keys of ``Result.tallies``)."""


# this thread's work arrays (``scratch``): a chunk's compacted events per bin, and the
# per-bin accumulators of the block in hand (zeroed here; the kernels reset what they touch)
_TALLY_BIN = WorkArray("tally-bin", np.int64)
_TALLY_SUMS = WorkArray("tally-sums", rows=3)
_TALLY_COUNT = WorkArray("tally-count", np.int64)
_TALLY_ACC = WorkArray("tally-acc", rows=3)
_TALLY_TOUCHED = WorkArray("tally-touched", np.int64)


def _accumulators(nbin: int) -> tuple:
    """This thread's zeroed per-bin accumulators (3, nbin) and event counts (nbin,): reused
    buffers, so that a chunk does not fault in fresh pages for them."""
    acc, touched = _TALLY_ACC(nbin), _TALLY_TOUCHED(nbin)
    acc.fill(0.0)
    touched.fill(0)
    return acc, touched


def split_tallies(status, weight, where, n_blocks: int, nbin: int) -> "ChunkTallies":
    """Per-block tallies of a batch of whole blocks (``tally_kernels.block_tallies``): for each
    block, its bins (sparse: only those it touches) with Σw, Σw², counts and Σ_pairs w w', and
    its ledger counts and Fresnel sums. Rays are added in ray order, so every block's sums
    are bitwise those of the block alone.

    Pair sum (paired strata, see ``bin_estimate``): rays 2k and 2k+1 of the run (one
    stratum; ``BLOCK`` is even and batches start on a block boundary, so pairs never straddle
    a block) contribute w_2k·w_2k+1 to their bin when both are single-bounce events in the
    same bin. A trailing unpaired ray (odd last block) has no partner and adds nothing."""
    n = len(status)
    acc, touched = _accumulators(nbin)
    out_bin, out_sums, out_cnt = _TALLY_BIN(n), _TALLY_SUMS(n), _TALLY_COUNT(n)
    offsets = np.empty(n_blocks + 1, dtype=np.int64)
    ln = np.zeros((n_blocks, len(LEDGER)), dtype=np.int64)
    lf = np.zeros((n_blocks, len(LEDGER)))
    tally_kernels.block_tallies(
        status, weight, where, BLOCK, acc, touched, out_bin, out_sums, out_cnt, offsets, ln, lf
    )
    used = int(offsets[-1])  # the blocks' bins, copied out of the work arrays
    return ChunkTallies(
        (out_bin[:used].copy(), out_sums[:, :used].copy(), out_cnt[:used].copy(), offsets, ln, lf)
    )


def chunk_tallies(path, nbin: int, blocks) -> "ChunkTallies":
    """Per-block tallies of the consecutive ``blocks`` followed by the trace path ``path``
    (``paths.TracePath``) over ``nbin`` bins: one thread task."""
    blocks = list(blocks)
    return split_tallies(*path.follow(blocks), len(blocks), nbin)


_NO_TIR = np.zeros(0, dtype=np.int8)


def split_order_tallies(
    status1, weight1, term, wterm, where, n_blocks: int, nbin_total: int, tir=None
):
    """``tallies.split_tallies`` for bounce chains (``tally_kernels.order_block_tallies``):
    per block, its (slot, bin) tallies and its ledger of 5 first-bounce + ``TERMINAL``
    classes. ``nbin_total`` = order slots × bins. ``tir``: for paths through a dielectric
    interface (``dielectric``), their total-internal-reflection bits; the ledger then has the
    ``DIELECTRIC_TERMINAL`` classes and the ``TIR_ORDERS`` columns (column k: the paths with
    bit k set, counted in both the count and the weight column)."""
    classes, tir_col = ledger_columns(tir is not None)
    sums = chunk_sums(len(term), n_blocks, nbin_total, classes)
    outcome = (status1, weight1, term, wterm, where, _NO_TIR if tir is None else tir)
    tally_kernels.order_block_tallies(outcome, BLOCK, sums, tir_col)
    return chunk_of(sums)


def ledger_columns(dielectric: bool) -> tuple[int, int]:
    """(columns, first total-internal-reflection column) of a bounce chain's per-block
    ledger: the first-bounce classes, the terminal ones (``DIELECTRIC_TERMINAL`` through a
    dielectric interface, else ``TERMINAL``) and, through an interface, ``TIR_ORDERS``."""
    terminal = DIELECTRIC_TERMINAL if dielectric else TERMINAL
    tir_col = len(LEDGER) + len(terminal)
    return tir_col + (len(TIR_ORDERS) if dielectric else 0), tir_col


def chunk_sums(n: int, n_blocks: int, nbin: int, classes: int) -> tally_kernels.ChunkSums:
    """The ``tally_kernels.ChunkSums`` of a chunk of ``n`` rays in ``n_blocks`` blocks over
    ``nbin`` tallies and ``classes`` ledger columns: this thread's work arrays, the dense
    ones zeroed, and fresh per-block ledgers."""
    acc, touched = _accumulators(nbin)
    return tally_kernels.ChunkSums(
        acc,
        touched,
        _TALLY_BIN(n),
        _TALLY_SUMS(n),
        _TALLY_COUNT(n),
        np.empty(n_blocks + 1, dtype=np.int64),
        np.zeros((n_blocks, classes), dtype=np.int64),
        np.zeros((n_blocks, classes)),
    )


def chunk_of(sums: tally_kernels.ChunkSums) -> "ChunkTallies":
    """The ``ChunkTallies`` of filled ``sums``: the blocks' bins copied out of the work arrays."""
    used = int(sums.offsets[-1])
    return ChunkTallies(
        (
            sums.out_bin[:used].copy(),
            sums.out_sums[:, :used].copy(),
            sums.out_cnt[:used].copy(),
            sums.offsets,
            sums.ln,
            sums.lf,
        )
    )


def chunk_order_tallies(path, nbin_total: int, blocks):
    """Per-block tallies of the consecutive ``blocks`` followed by a bounce-chain ``path``
    (its outcome a ``bounces.ChainOutcome``, or a ``dielectric.InterfaceOutcome`` with the
    paths' total-internal-reflection bits): one thread task."""
    blocks = list(blocks)
    outcome = path.follow(blocks)._asdict()
    return split_order_tallies(**outcome, n_blocks=len(blocks), nbin_total=nbin_total)


class ChunkTallies:
    """The per-block tallies of one chunk (``split_tallies``), handed out once (``take``):
    taking releases them, so a finished future its caller still holds keeps no arrays
    (memory stays independent of the number of rays)."""

    def __init__(self, parts: tuple):
        self._parts = parts
        self.blocks = len(parts[3]) - 1

    def take(self) -> tuple:
        """(bins, sums (3, ·), counts, offsets, ledger counts, ledger Fresnel sums)."""
        parts, self._parts = self._parts, None
        if parts is None:
            raise RuntimeError("these chunk tallies were already taken")
        return parts

    @classmethod
    def joined(cls, chunks: list) -> "ChunkTallies":
        """The tallies of consecutive blocks tallied in parts (``chunks``, in block order) as
        one chunk's."""
        if len(chunks) == 1:
            return chunks[0]
        parts = [c.take() for c in chunks]
        starts = np.cumsum([0] + [len(p[0]) for p in parts])
        offsets = [p[3][:-1] + s for p, s in zip(parts, starts)] + [starts[-1:]]
        return cls(
            (
                np.concatenate([p[0] for p in parts]),
                np.concatenate([p[1] for p in parts], axis=1),
                np.concatenate([p[2] for p in parts]),
                np.concatenate(offsets),
                np.concatenate([p[4] for p in parts]),
                np.concatenate([p[5] for p in parts]),
            )
        )


@dataclass
class Tally:
    """Running sums over the rays of one (realisation, incidence) — or of several, pooled —
    added block by block in block order: per bin Σw, Σw², event counts, Σ pairs w_2k w_2k+1
    and, over the blocks (S_b a block's Σw in the bin, m_b its rays), Σ_b S_b² and
    Σ_b m_b S_b; per ledger class (``LEDGER``) ray counts and Fresnel sums."""

    sum_w: np.ndarray
    sum_w2: np.ndarray
    count: np.ndarray
    led_n: np.ndarray
    led_f: np.ndarray
    sum_pair: np.ndarray
    sum_block2: np.ndarray
    sum_block_rays: np.ndarray

    @classmethod
    def empty(cls, nbin: int, classes: int = len(LEDGER)) -> "Tally":
        """Zero sums over ``nbin`` tally slots (bins, or order slots × bins for bounce
        chains) and ``classes`` ledger columns (``bounces.ledger_classes``)."""
        return cls(
            np.zeros(nbin),
            np.zeros(nbin),
            np.zeros(nbin, np.int64),
            np.zeros(classes, np.int64),
            np.zeros(classes),
            np.zeros(nbin),
            np.zeros(nbin),
            np.zeros(nbin),
        )

    def items(self) -> tuple:
        """The sums in the order of ``TALLY_NAMES``."""
        return tuple(getattr(self, name) for name in TALLY_NAMES)

    def add_chunk(self, chunk: ChunkTallies) -> int:
        """Add a chunk's per-block tallies, block by block in block order (callers add chunks
        in block order; ``tally_kernels.add_blocks``); returns the number of blocks added."""
        tally_kernels.add_blocks(
            self.sum_w,
            self.sum_w2,
            self.count,
            self.sum_pair,
            self.sum_block2,
            self.sum_block_rays,
            self.led_n,
            self.led_f,
            len(LEDGER),
            chunk.take(),
        )
        return chunk.blocks

    def add_totals(self, other: "Tally") -> None:
        """Add another tally's running sums (pooling realisations, or independent runs)."""
        for total, part in zip(self.items(), other.items()):
            total += part

    def estimate(self, rays, omega: np.ndarray, method: str):
        """BRDF and standard error (sr⁻¹, flat) of these sums over ``rays`` primary rays — an
        int, or for pooled realisations the rays of each (``bin_estimate``; ``method`` one of
        ``STDERR_METHODS``)."""
        n = int(np.sum(rays))
        if method == "pairs":
            pairs = PairSums(self.sum_pair, self.count)
            return bin_estimate(self.sum_w, self.sum_w2, n, omega, pairs=pairs)
        if method == "blocks":
            blocks = BlockSums(self.sum_block2, self.sum_block_rays, *block_sizes(rays))
            return bin_estimate(self.sum_w, self.sum_w2, n, omega, blocks=blocks)
        return bin_estimate(self.sum_w, self.sum_w2, n, omega)


STDERR_METHODS = ("pairs", "blocks", "per-ray")
"""How a run's standard error is estimated (``meta["stderr_method"]``, ``bin_estimate``):
paired strata (stratified origins), the scatter between blocks (``isotropic`` runs, every
block an independent replicate), or the i.i.d. per-ray formula (independent origins)."""


@dataclass(frozen=True)
class PairSums:
    """The pair tallies of ``bin_estimate``'s paired-strata error: per bin Σ_k x_2k x_2k+1
    and the events (``Tally.sum_pair``, ``Tally.count``)."""

    sum_pair: np.ndarray
    count: np.ndarray


@dataclass(frozen=True)
class BlockSums:
    """The block tallies of ``bin_estimate``'s "blocks" error: per bin Σ_b S_b² and
    Σ_b m_b S_b (``Tally``), and the blocks' count and Σ_b m_b²."""

    sum_block2: np.ndarray
    sum_block_rays: np.ndarray
    blocks: int
    sum_rays2: float


def block_sizes(rays) -> tuple[int, float]:
    """(blocks, Σ_b m_b²) of runs of ``rays`` primary rays each (an int or a sequence: one per
    pooled realisation), cut into blocks of ``BLOCK`` rays, the last one short."""
    n = np.atleast_1d(np.asarray(rays, dtype=np.int64))
    full, rest = n // BLOCK, n % BLOCK
    return int(np.sum(full + (rest > 0))), float(np.sum(full * float(BLOCK) ** 2 + rest**2.0))


STDERR_RULE = 2
"""Version of ``bin_estimate``'s rule (which error serves where): a cached result, whose
standard errors are stored, must share it (``microsim.testing``'s cache key). 2: paired strata
where a bin has ``MIN_EVENTS`` events and ``MIN_DISCORDANT`` discordant pairs."""

MIN_DISCORDANT = 5
"""Discordant pairs (their equivalent N_B (Σx² − 2Σ pairs)/Σx²) a bin needs for its pair error:
with fewer, that error has almost no degrees of freedom (every pair of a rare bin landing in
it with near-equal weights makes it ~0) and the per-ray formula serves instead."""


def pair_error_trusted(sum_w2, diff, count):
    """(where the paired-strata error serves, the bins' discordant pairs ν = N_B·diff/Σx²) for
    per-bin Σx², diff = Σx² − 2Σ pairs and event counts N_B: at least ``stats.MIN_EVENTS``
    events, ``MIN_DISCORDANT`` discordant pairs and a difference above its rounding level
    (64 ε Σx²). ν is exactly the discordant pairs when the bin's weights are equal."""
    with np.errstate(invalid="ignore", divide="ignore"):
        discordant = np.where(sum_w2 > 0, count * diff / np.where(sum_w2 > 0, sum_w2, 1.0), 0.0)
    trusted = (
        (diff > 64 * np.finfo(float).eps * sum_w2)
        & (count >= MIN_EVENTS)
        & (discordant >= MIN_DISCORDANT)
    )
    return trusted, discordant


def stderr_dof(result) -> np.ndarray | None:
    """Degrees of freedom ν (T, Θ, Φ) of ``result``'s ray-noise standard error
    (``stderr_ray``, or ``stderr`` with one realisation) per single-bounce bin, from its raw
    tallies (None without them: the error is then taken as exact). Paired strata: the sum
    Σ_k (x_2k − x_2k+1)² has as many non-zero terms as the bin has discordant pairs (one ray
    in the bin, the other not, or unequal weights), so ν = N_B (Σx² − 2Σ pairs)/Σx² — exactly
    the discordant pairs when the bin's weights are equal; where the per-ray formula serves
    (``bin_estimate``'s rule), N_B − 1. Blocks: B − 1. Per-ray: N_B − 1. At least 1."""
    t = result.tallies
    if t is None:
        return None
    nb = result.bins.shape[0] * result.bins.shape[1]
    count, sum_w2 = (np.asarray(t[k]).sum(axis=0)[:, :nb] for k in ("count", "sum_w2"))
    method = result.meta.get("stderr_method")
    nu = count - 1.0
    if method == "pairs" and "sum_pair" in t:
        diff = sum_w2 - 2.0 * np.asarray(t["sum_pair"]).sum(axis=0)[:, :nb]
        trusted, discordant = pair_error_trusted(sum_w2, diff, count)
        nu = np.where(trusted, discordant, nu)
    elif method == "blocks":
        blocks = [block_sizes(rays)[0] for rays in np.asarray(t["rays"]).T]
        nu = np.broadcast_to(np.array(blocks, float)[:, None] - 1.0, count.shape)
    return np.maximum(nu, 1.0).reshape((len(result.theta_i),) + result.bins.shape)


def bin_estimate(
    sum_w, sum_w2, n, omega, pairs: PairSums | None = None, blocks: BlockSums | None = None
):
    """BRDF and standard error of one tally (sr⁻¹); NaN when no ray was traced.

    ``sum_w``/``sum_w2`` per-bin Σx, Σx²; ``n`` primary rays; ``omega`` per-bin projected
    solid angle (sr). With x_r = w_r·1[ray r in bin B] the bin mean is Σx/N. Per-ray (i.i.d.)
    error:
        se² = (Σx²/N − (Σx/N)²)/(N − 1).
    ``pairs`` given (stratified origins): paired strata — rays (2k, 2k+1) are two
    independent samples of one stratum of width 2/N, so E[(x_2k − x_2k+1)²] = 2σ²_k and
        se² = Σ_k (x_2k − x_2k+1)²/N² = (Σx² − 2 Σ_k x_2k x_2k+1)/N²
    is unbiased (a trailing unpaired ray, alone in its stratum, counts as paired with 0,
    adding x²/N²: conservative, one ray).
    Rule (``pair_error_trusted``): the pair estimate, clipped at ≥ 0, is used where the bin
    holds at least ``stats.MIN_EVENTS`` events and ``MIN_DISCORDANT`` discordant pairs, and
    Σx² − 2Σ_k x_2k x_2k+1 exceeds the rounding level of that difference (64 ε Σx²);
    elsewhere the per-ray formula (the variance of unstratified sampling, which
    stratification never exceeds in expectation) is used instead. The pair estimate has as
    many degrees of freedom as the bin has discordant pairs: a bin whose pairs nearly all
    land in it together with near-equal weights gets an error of ~0, and one whose pairs all
    hold two equal weights would get a zero error (stratified sampling with two units per stratum,
    Cochran, Sampling Techniques, 3rd ed., §5.5).
    ``blocks`` given (``isotropic`` runs): every block b is an independent replicate of one
    design (its own sweep of the tile, its own incidence azimuth), with S_b its Σx and m_b its
    rays, so the mean is the ratio estimate f = Σ_b S_b / Σ_b m_b over B blocks, with
        se² = B/(B − 1) · Σ_b (S_b − m_b f)² / N²
            = B/(B − 1) · (Σ S_b² − 2 f Σ m_b S_b + f² Σ m_b²) / N²
    (the variance of a ratio estimate, Cochran, Sampling Techniques, ch. 6: unbiased for
    equal blocks, to O(1/B) with the last one short). NaN with fewer than two blocks."""
    if n < 1:
        return np.full_like(sum_w, np.nan), np.full_like(sum_w, np.nan)
    mean = sum_w / n
    var = np.maximum(sum_w2 / n - mean * mean, 0.0) / (n - 1) if n > 1 else np.nan
    if blocks is not None:
        b = blocks
        spread = b.sum_block2 - 2 * mean * b.sum_block_rays + mean * mean * b.sum_rays2
        var = np.maximum(spread, 0.0) / (float(n) * n)
        var = var * b.blocks / (b.blocks - 1) if b.blocks > 1 else np.full_like(mean, np.nan)
    elif pairs is not None:
        diff = sum_w2 - 2.0 * pairs.sum_pair
        pair = np.maximum(diff, 0.0) / (float(n) * n)
        trusted, _ = pair_error_trusted(sum_w2, diff, pairs.count)
        var = np.where(trusted, pair, var)
    se = np.sqrt(var) * np.ones_like(mean)
    return mean / omega, se / omega


def tally_result(
    theta_i,
    phi_i,
    bins: Bins,
    totals,
    rays,
    brdf,
    stderr,
    meta: dict,
    tallies: dict | None = None,
    **extra,
) -> Result:
    """A ``Result`` from the pooled sums ``totals`` (one ``Tally`` per incidence) over
    ``rays`` (T,) primary rays, with ``brdf``/``stderr`` (T, Θ·Φ) already estimated: ledger
    fractions and counts, per-bin counts and sums; ``tallies`` and ``extra`` are passed on."""
    shape = (len(theta_i),) + bins.shape
    led_n = np.array([p.led_n for p in totals])
    led_f = np.array([p.led_f for p in totals])
    with np.errstate(divide="ignore", invalid="ignore"):
        ledger = {name: led_n[:, k] / rays for k, name in enumerate(LEDGER)}
        for k, name in enumerate(LEDGER[:3]):
            ledger[f"{name}_fresnel"] = led_f[:, k] / rays
        ledger["lost"] = (led_n[:, MASKED] + led_n[:, DOWNWARD]) / rays
        ledger["lost_fresnel"] = (led_f[:, MASKED] + led_f[:, DOWNWARD]) / rays
    counts = {name: led_n[:, k] for k, name in enumerate(LEDGER)}
    if led_n.shape[1] > len(LEDGER):  # bounce chains: the paths' terminal classes
        ledger.update(terminal_ledger(led_n[:, len(LEDGER) :], led_f[:, len(LEDGER) :], rays))
        names = TERMINAL if led_n.shape[1] == len(LEDGER) + len(TERMINAL) else DIELECTRIC_COLUMNS
        counts.update({name: led_n[:, len(LEDGER) + k] for k, name in enumerate(names)})
    return Result(
        theta_i=theta_i,
        phi_i=np.asarray(phi_i, dtype=np.float64),
        bins=bins,
        brdf=np.asarray(brdf).reshape(shape),
        stderr=np.asarray(stderr).reshape(shape),
        rays=np.asarray(rays).astype(np.int64),
        ledger=ledger,
        ledger_counts=counts,
        counts=np.array([p.count for p in totals]).reshape(shape),
        sum_w=np.array([p.sum_w for p in totals]).reshape(shape),
        sum_w2=np.array([p.sum_w2 for p in totals]).reshape(shape),
        meta=meta,
        tallies=tallies,
        **extra,
    )


TRANSMITTED_ARRAYS = {
    "brdf_orders": "btdf_orders",
    "stderr_orders": "stderr_btdf_orders",
    "brdf_realisations_orders": "btdf_realisations_orders",
}
"""A dielectric interface's Result arrays: the reflected one → its transmitted twin."""


def terminal_ledger(led_n, led_f, rays) -> dict:
    """Ledger entries (name → (T,)) of bounce chains from their terminal-class columns
    (T, ``TERMINAL``, or ``DIELECTRIC_COLUMNS`` for a dielectric interface) of path counts ``led_n``
    and carried weights ``led_f`` over ``rays`` (T,) primary rays: per class ``<name>`` the
    fraction of paths and ``<name>_energy`` the fraction of the incident energy it takes
    away; ``escaped_energy`` (all orders; for a dielectric, left on the incidence's side: R),
    ``transmitted_energy`` (a dielectric's T), ``cut_energy`` (bounce limit + weight floor)
    and ``absorbed_energy`` = 1 − Σ of all classes' energies (the Fresnel losses
    Σ_paths (1 − Π_b F_b), over N); a dielectric's ``tir_<k>``: the fraction of paths totally
    internally reflected at their k-th interaction."""
    dielectric = led_n.shape[1] == len(DIELECTRIC_COLUMNS)
    classes = DIELECTRIC_TERMINAL if dielectric else TERMINAL
    out = {}
    with np.errstate(divide="ignore", invalid="ignore"):
        for k, name in enumerate(classes):
            out[name] = led_n[:, k] / rays
            out[f"{name}_energy"] = led_f[:, k] / rays
        out["escaped_energy"] = led_f[:, :4].sum(axis=1) / rays
        out["cut_energy"] = led_f[:, 4:6].sum(axis=1) / rays
        if dielectric:
            out["transmitted_energy"] = led_f[:, len(TERMINAL) : len(classes)].sum(axis=1) / rays
            for k, name in enumerate(TIR_ORDERS):
                out[name] = led_n[:, len(classes) + k] / rays
        out["absorbed_energy"] = (rays - led_f[:, : len(classes)].sum(axis=1)) / rays
    return out


def simulation_result(
    theta_i,
    phi_i,
    bins: Bins,
    tallies,
    rays_done,
    rays_planned,
    blocks_done,
    meta: dict,
    slots: int | None = None,
) -> Result:
    """``simulate``'s Result from the running sums ``tallies`` [r][i] (``Tally``):
    ``rays_done`` (R, T) rays tallied per realisation and incidence (== ``rays_planned`` (R,)
    for a complete run), ``blocks_done`` (R, T). The BRDF pools all realisations; with
    several, ``stderr`` adds to the ray noise the realisation component: what the scatter of
    the realisation means exceeds the ray noise by.

    ``slots``: None for single-bounce tallies; for bounce chains the number of order slots O
    (``bounces.order_slots``): the tallies then hold O·(Θ·Φ) slots (slot o·(Θ·Φ) + B), every
    estimate is made per slot exactly as for one bin, and the Result gets ``brdf_orders``/
    ``stderr_orders`` (O, T, Θ, Φ) (and ``brdf_realisations_orders`` (O, R, T, Θ, Φ)) while
    ``brdf``, ``stderr``, ``counts``, ``sum_w``… hold order 1. With ``meta["transmission"]``
    (a dielectric interface) the 2O slots are O reflected then O transmitted order slots:
    ``btdf_orders``/``stderr_btdf_orders`` (and ``btdf_realisations_orders``) get the
    transmitted ones (``TRANSMITTED_ARRAYS``)."""
    nb = bins.shape[0] * bins.shape[1]
    omega = np.tile(bins.projected_solid_angle().ravel(), 1 if slots is None else slots)
    shape = (len(theta_i),) + bins.shape
    n_real = len(rays_planned)
    n_tot = rays_done.sum(axis=0)
    classes = len(tallies[0][0].led_n)
    pooled = [Tally.empty(len(omega), classes) for _ in theta_i]
    for r in range(n_real):
        for i in range(len(theta_i)):
            pooled[i].add_totals(tallies[r][i])
    method = meta["stderr_method"]
    brdf, se_ray = map(
        np.array,
        zip(*[p.estimate(rays_done[:, i], omega, method) for i, p in enumerate(pooled)]),
    )
    extra = {}
    stderr = se_ray
    if n_real > 1:
        per = np.array(
            [
                [
                    tallies[r][i].estimate(rays_done[r, i], omega, "per-ray")[0]
                    for i in range(len(theta_i))
                ]
                for r in range(n_real)
            ]
        )
        # scatter of the realisation means estimates the total variance of their mean (ray
        # noise included); the realisation component is what exceeds the ray noise
        total_var = np.full(per.shape[1:], np.nan)
        for i in range(len(theta_i)):
            have = rays_done[:, i] > 0
            if have.sum() > 1:
                total_var[i] = np.var(per[have, i], axis=0, ddof=1) / have.sum()
        se_real = np.sqrt(np.maximum(total_var - se_ray**2, 0.0))
        stderr = np.sqrt(se_ray**2 + se_real**2)
        extra = {
            "stderr_ray": se_ray[:, :nb].reshape(shape),
            "stderr_realisation": se_real[:, :nb].reshape(shape),
            "brdf_realisations": per[:, :, :nb].reshape((n_real,) + shape),
            "rays_realisations": np.array(rays_planned, dtype=np.int64),
        }
        if slots is not None:
            extra["brdf_realisations_orders"] = np.moveaxis(
                per.reshape((n_real, len(theta_i), slots) + bins.shape), 2, 0
            )
    raw = tally_arrays(tallies, blocks_done, rays_done)
    if slots is None:
        return tally_result(theta_i, phi_i, bins, pooled, n_tot, brdf, stderr, meta, raw, **extra)
    by_order = lambda a: np.moveaxis(a.reshape((len(theta_i), slots) + bins.shape), 1, 0)  # noqa: E731
    extra.update(brdf_orders=by_order(brdf), stderr_orders=by_order(stderr))
    if meta.get("transmission"):  # reflected order slots, then transmitted ones
        o = slots // 2
        for name, btdf_name in TRANSMITTED_ARRAYS.items():
            if name in extra:
                a = extra[name]
                extra[name], extra[btdf_name] = a[:o], a[o:]
    ledger = ("led_n", "led_f")  # per class, not per slot
    first = [
        Tally(*(a if k in ledger else a[:nb] for k, a in zip(TALLY_NAMES, p.items())))
        for p in pooled
    ]
    return tally_result(
        theta_i, phi_i, bins, first, n_tot, brdf[:, :nb], stderr[:, :nb], meta, raw, **extra
    )


def tally_arrays(tallies, blocks_done, rays_done) -> dict:
    """The exact running sums [r][i] as ``Result.tallies`` arrays: each of ``TALLY_NAMES``
    (R, T, ·), ``blocks`` (R, T) blocks done and ``rays`` (R, T) rays tallied."""
    raw = {
        name: np.array([[getattr(t, name) for t in row] for row in tallies]) for name in TALLY_NAMES
    }
    raw.update(blocks=np.array(blocks_done), rays=np.asarray(rays_done).astype(np.int64))
    return raw


def tallies_from_arrays(arrays: dict, n_real: int, n_incidences: int) -> list:
    """The running sums [r][i] (``Tally``, copies) stored in ``Result.tallies`` arrays."""
    return [
        [Tally(*(np.array(arrays[k][r, i]) for k in TALLY_NAMES)) for i in range(n_incidences)]
        for r in range(n_real)
    ]

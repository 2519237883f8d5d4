"""One step of a path through a dielectric interface (``dielectric.trace_dielectric``,
``interface_step``): per live path, the hit's side, the exact unpolarised Fresnel reflectance
F of the dielectric interface (total internal reflection: F = 1), the choice between the
reflected and the refracted ray, the terminal class of a path that ends and the next ray of one
that goes on.

Geometry: facet normals n point up (out of the medium, into the air). A path's ray travels along
d; at a hit, c = −d·n > 0 means it arrives from above (air, index 1, onto the medium of index η),
c < 0 from below (inside the medium, onto air). Each path carries which side it is on
(``inside``); a hit from the other side than the path's (a numerical leak through a facet) ends
it as unresolved. With the normal n_s = sign(c)·n facing the arriving ray, c_i = |c| and the
relative index r = η_i/η_t of the crossing:

* reflected:  d + 2c·n (the mirror direction; the path stays on its side);
* refracted:  r·d + (r·c_i − c_t)·n_s, c_t = √(1 − r²(1 − c_i²)) (Snell's law in vector form;
  the path changes side). Beyond the critical angle (r²(1 − c_i²) ≥ 1) F = 1: always reflected.

Russian roulette: a lossless interface (real η) reflects with probability F and refracts
otherwise, the path's weight staying 1, so R and T are fractions of paths and every primary
ray ends in exactly one class (the energy ledger closes ray by ray); splitting the weight
instead would double the rays at every interaction. The uniform of path g at interaction b
is ``path_uniform(stream, ray0 + g, b)``: a counter-based hash of the path's number in its
incidence, so a path's choices never depend on its chunk or thread. An absorbing medium
(complex η = n + ik, k > 0: its bulk is opaque) keeps no transmitted light: the path reflects
with the weight F (``fresnel_real_scalar`` onto η²), as in the opaque chain of
``bounce_kernels``, and what is refracted counts as absorbed.

Ends (at step b the ray traced is the primary ray, b = 1, or the continuation chosen at
interaction b − 1): a ray leaving the relief upward (ESCAPED) or downward (MISSED while
falling: below the relief's bottom) at b ≥ 2 ends the path after order b − 1 as reflected
(ESC_*, left on the incidence's side) or transmitted (TRANS_*, the other side), its direction
listed in ``Escapes`` (z flipped for downward escapes, so both hemispheres share one bin grid:
θo measured from the pole of the side it leaves by); a primary ray without a hit is a leak
(PATH_MISSED; PATH_UNRESOLVED at the wrap cap), as is a ray leaving the relief through the
side it is not on (a ray in the air below the bottom, or inside the medium above the top); a
hit at b > limit is CUT_BOUNCES; an absorbing medium's weight below ``floor`` is CUT_WEIGHT.
New starts lie on the facet plane, eps on the side the new ray leaves to. ``tir`` gathers per
path a bit per interaction order (1, 2, 3, ≥ 4) at which it was totally internally reflected.

The first-interaction ledger (``status1``, ``weight1``): SINGLE if the continuation of the first
interaction escaped, MASKED if it met the surface again, RAY_UNRESOLVED / RAY_MISSED if a walk
failed; weight1 is that interaction's weight (1 for a lossless interface, F for an absorbing
one).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from microsim.analytic.fresnel import fresnel_real_scalar
from microsim.bin_kernels import locate_folded
from microsim.jit import compiled, inlined

from .bounce_kernels import continue_path, end_path, end_unresolved
from .engine.beam import beam_escapes
from .engine.codes import (
    CUT_BOUNCES,
    CUT_WEIGHT,
    ESCAPED,
    HIT,
    MASKED,
    MISSED,
    PATH_MISSED,
    PATH_UNRESOLVED,
    RAY_MISSED,
    RAY_UNRESOLVED,
    SINGLE,
    TRANS_1,
    UNRESOLVED,
    order_class,
)
from .engine.facets import facet_plane
from .engine.horizon import rises_clear

GOLDEN = np.uint64(0x9E3779B97F4A7C15)  # SplitMix64's Weyl increment
STEP_BITS = 9  # interactions per path in a counter: MAX_BOUNCES + 1 ≤ 2⁹


class Interface(NamedTuple):
    """The interface as the kernel takes it: ``eta2`` = n², ``k2`` = k² of the medium's index
    η = n + ik (air above has index 1), ``absorbing`` (k > 0: its bulk keeps what it
    refracts), ``eps`` the offset of a new ray's start from its facet plane."""

    eta2: float
    k2: float
    absorbing: bool
    eps: float


class Roulette(NamedTuple):
    """The random stream of one incidence's paths: ``stream`` (uint64, from its key) and
    ``ray0``, the number within the incidence of the chunk's first path."""

    stream: np.uint64
    ray0: int


class PathSides(NamedTuple):
    """Per path of the chunk (global index): whether its ray is inside the medium
    (``inside``), whether it was lit from below (``from_below``, one value for the chunk) and
    its total-internal-reflection bits ``tir`` (bit k: at interaction order k + 1; bit 3: at
    an order ≥ 4)."""

    inside: np.ndarray
    from_below: bool
    tir: np.ndarray


class SideEscapes(NamedTuple):
    """Paths escaping at this step: global index, direction flipped into the upper
    hemisphere when it leaves downward, and whether it is transmitted."""

    index: np.ndarray
    dx: np.ndarray
    dy: np.ndarray
    dz: np.ndarray
    transmitted: np.ndarray


@inlined
def _mix(z):
    """SplitMix64's output function (a bijection of uint64 with full avalanche)."""
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


@inlined
def path_uniform(stream, ray, step):
    """A uniform in [0, 1) for interaction ``step`` of path number ``ray``: the SplitMix64
    stream ``stream`` at position ray·2^STEP_BITS + step (53 bits)."""
    counter = (np.uint64(ray) << np.uint64(STEP_BITS)) | np.uint64(step)
    z = _mix(stream + counter * GOLDEN)
    return np.float64(z >> np.uint64(11)) * (1.0 / 9007199254740992.0)


ENDS, ESCAPES, CONTINUES = 0, 1, 2
"""What ``interact`` makes of a path's step: it ended (in the ledger), it leaves the relief
on its own side (``end_escape``), or it goes on along a new ray."""


@inlined
def end_escape(ledger, sides, b, g, w, dz):
    """End path ``g``, whose ray along (·, ·, ``dz``) leaves the relief after order b − 1 with
    weight ``w``: reflected if it leaves on the incidence's side, else transmitted (returned)."""
    transmitted = (dz < 0.0) != sides.from_below
    cls = order_class(b - 1)
    end_path(ledger, g, TRANS_1 + cls if transmitted else cls, w)
    return transmitted


@inlined
def _escape(ledger, escapes, sides, b, g, w, d, e):
    """``end_escape`` of path ``g`` along ``d``, listed in ``escapes`` at slot ``e`` (direction
    flipped up if it falls). Returns the number of escapes listed."""
    dx, dy, dz = d
    escapes.transmitted[e] = end_escape(ledger, sides, b, g, w, dz)
    escapes.index[e] = g
    escapes.dx[e], escapes.dy[e] = dx, dy
    escapes.dz[e] = -dz if dz < 0.0 else dz
    return e + 1


@inlined
def crossing(c, inside, interface):
    """(rel2, F, tir) of a hit with c = −d·n ≠ 0 by a ray ``inside`` the medium or not:
    (η_t/η_i)², the Fresnel reflectance (``fresnel_real_scalar``; 1 at total internal
    reflection) and whether it is totally internally reflected, sin²θi ≥ (η_t/η_i)²."""
    ci = abs(c)
    rel2 = 1.0 / interface.eta2 if inside else interface.eta2  # (η_t/η_i)²
    fw = fresnel_real_scalar(ci, rel2, 0.0 if inside else interface.k2)
    return rel2, fw, not interface.absorbing and (1.0 - ci * ci) >= rel2


@inlined
def scatter(d, n, c, rel2, reflect):
    """The direction leaving a hit with c = −d·n on the facet of unit normal ``n``:
    reflected, d + 2c·n, or refracted (module docstring; (η_t/η_i)² = ``rel2``, below the
    critical angle)."""
    dx, dy, dz = d
    a0, a1, a2 = n
    if reflect:
        return dx + 2.0 * c * a0, dy + 2.0 * c * a1, dz + 2.0 * c * a2
    ci = abs(c)
    s = 1.0 if c > 0.0 else -1.0  # n_s = s·n faces the arriving ray
    r = 1.0 / math.sqrt(rel2)
    ct = math.sqrt(max(1.0 - r * r * (1.0 - ci * ci), 0.0))
    k = (r * ci - ct) * s
    return r * dx + k * a0, r * dy + k * a1, r * dz + k * a2


@inlined
def interact(b, limit, floor, g, w, h, f, d, facets, interface, roulette, sides, ledger):
    """Step ``b`` of path ``g`` (weight ``w``) whose ray along ``d`` ended with walk status
    ``h`` on face ``f`` (module docstring): (what, wn, ox, oy, oz, offset) — ``what`` one of
    ENDS (the ledger written), ESCAPES (the ray left the relief on the path's side:
    ``end_escape`` is the caller's) or CONTINUES along (ox, oy, oz) with weight ``wn`` from
    the hit moved along the facet's unit normal ``n`` onto the plane n·x = ``offset`` (eps on
    the side the ray leaves to): (what, wn, ox, oy, oz, offset, n).
    ``facets``: ``bounce_kernels.FacetPlanes``; ``sides`` and ``ledger`` are updated."""
    none = (0.0, 0.0, 0.0)
    dx, dy, dz = d
    leaves_down = h == MISSED and dz < 0.0
    if b == 2 and ledger.status1[g] == SINGLE and not (h == ESCAPED or leaves_down):
        ledger.status1[g] = (
            MASKED if h == HIT else (RAY_UNRESOLVED if h == UNRESOLVED else RAY_MISSED)
        )
    if b >= 2 and (h == ESCAPED or leaves_down) and leaves_down == sides.inside[g]:
        return ESCAPES, w, 0.0, 0.0, 0.0, 0.0, none
    if h != HIT:
        walk_failed = RAY_UNRESOLVED if h == UNRESOLVED else RAY_MISSED
        path_failed = PATH_UNRESOLVED if h == UNRESOLVED else PATH_MISSED
        end_unresolved(ledger, b, g, w, path_failed, walk_failed)
        return ENDS, w, 0.0, 0.0, 0.0, 0.0, none
    if b > limit:
        end_path(ledger, g, CUT_BOUNCES, w)
        return ENDS, w, 0.0, 0.0, 0.0, 0.0, none
    absorbing, eps = interface.absorbing, interface.eps
    a0, a1, a2, plane = facet_plane(facets.facets, f)
    n = (a0, a1, a2)
    c = -(dx * a0 + dy * a1 + dz * a2)
    inside = sides.inside[g]
    if c == 0.0 or (c < 0.0) != inside:  # met from the side the path is not on
        end_unresolved(ledger, b, g, w, PATH_UNRESOLVED, RAY_UNRESOLVED)
        return ENDS, w, 0.0, 0.0, 0.0, 0.0, none
    rel2, fw, tir = crossing(c, inside, interface)
    if tir:
        sides.tir[g] |= np.int8(1 << (min(b, 4) - 1))
    if absorbing or tir:
        reflect, wn = True, w * fw  # fw = 1 at total internal reflection
    else:
        reflect = path_uniform(roulette.stream, roulette.ray0 + g, b) < fw
        wn = w
    if b == 1:
        ledger.weight1[g] = wn
        ledger.status1[g] = SINGLE
    ox, oy, oz = scatter(d, n, c, rel2, reflect)
    if not reflect:
        sides.inside[g] = not inside
    if wn < floor:
        end_path(ledger, g, CUT_WEIGHT, wn)
        return ENDS, wn, 0.0, 0.0, 0.0, 0.0, none
    above = ox * a0 + oy * a1 + oz * a2 > 0.0
    lift = plane + facets.facets.eps
    return CONTINUES, wn, ox, oy, oz, (lift if above else lift - 2.0 * eps), n


@compiled
def interface_step(
    b, limit, floor, live, w, walk, rays, facets, interface, roulette, sides, ledger, escapes, nxt
):
    """One step ``b`` of the paths through a dielectric interface (``interact`` per path):
    returns (continuing paths m, escapes e).

    Arguments: step ``b``, interaction ``limit``, weight ``floor``, the live paths' global
    indices ``live`` and weights ``w``; ``walk`` (``engine.segments.WalkResult`` of the rays
    traced at this step), ``rays`` (``bounce_kernels.RayDirections``), ``facets``
    (``bounce_kernels.FacetPlanes``: lift n·v0 + eps), ``interface`` (``Interface``),
    ``roulette`` (``Roulette``), ``sides`` (``PathSides``, updated), ``ledger``
    (``bounce_kernels.PathLedger``, written), ``escapes`` (``SideEscapes``, written) and
    ``nxt`` (``bounce_kernels.NextRays``, written)."""
    hs, prim, px, py, pz = walk
    dx, dy, dz, shared = rays
    m = 0
    e = 0
    for i in range(len(live)):
        g = live[i]
        j = 0 if shared else i
        d = (dx[j], dy[j], dz[j])
        f = prim[i]
        what, wn, ox, oy, oz, offset, n = interact(
            b, limit, floor, g, w[i], hs[i], f, d, facets, interface, roulette, sides, ledger
        )
        if what == ESCAPES:
            e = _escape(ledger, escapes, sides, b, g, w[i], d, e)
        elif what == CONTINUES:
            half = (facets.half_x, facets.half_y)
            continue_path(nxt, m, g, (px[i], py[i], pz[i]), n, offset, half, (ox, oy, oz), wn)
            m += 1
    return m, e


TRACED = -2
"""``InterfaceTable.bin`` of a choice whose ray must be traced (it may meet the surface)."""
FACES_AWAY = 1
TOTAL_REFLECTION = 2
"""``InterfaceTable.flags`` bits: the facet faces away from the primary ray (its paths take
``interact``'s checks), or reflects it totally."""


@compiled
def first_interactions(facets, d, inside, interface, leaving, binning, weight, flags, bins):
    """Per facet of ``facets`` (``engine.facets.Facets``: unit normal n), the first
    interaction of a primary ray along ``d`` (3 floats) on the ``inside`` side
    (``interact``'s arithmetic, so the same values): ``weight`` its Fresnel F, ``flags``
    (FACES_AWAY, TOTAL_REFLECTION) and per choice (0 reflected, 1 refracted) ``bins`` the bin
    its ray escapes into when it surely leaves the relief (``bin_kernels.locate_folded`` on
    ``binning``, −1 outside the grid), else TRACED. ``leaving`` = (slope, above, below): rays
    away from their side's surface more steeply than ``slope``·|o_h| surely leave, and so do
    those of a facet whose whole beam clears the relief (``engine.beam.beam_escapes`` on the
    ``BeamGrid`` ``above``, or on ``below``, the relief upside down, for rays leaving
    downward below the surface)."""
    slope, beam_above, beam_below = leaving
    for f in range(facets.count):
        a0, a1, a2, _ = facet_plane(facets, f)
        n = (a0, a1, a2)
        c = -(d[0] * n[0] + d[1] * n[1] + d[2] * n[2])
        bins[f, 0], bins[f, 1] = TRACED, TRACED
        if c == 0.0 or (c < 0.0) != inside:
            weight[f], flags[f] = 0.0, FACES_AWAY
            continue
        rel2, fw, tir = crossing(c, inside, interface)
        weight[f], flags[f] = fw, TOTAL_REFLECTION if tir else 0
        for k in range(1 if tir else 2):
            ox, oy, oz = scatter(d, n, c, rel2, k == 0)
            below = inside if k == 0 else not inside
            if rises_clear(ox, oy, -oz if below else oz, slope) or (
                beam_escapes(f, (ox, oy, -oz), beam_below)
                if below
                else beam_escapes(f, (ox, oy, oz), beam_above)
            ):
                bins[f, k] = locate_folded(
                    ox, oy, abs(oz), binning.ex, binning.ey, binning.phi_deg,
                    binning.n_theta, binning.edges, binning.scales,
                )  # fmt: skip

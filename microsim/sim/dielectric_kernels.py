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
from microsim.jit import compiled, inlined

from .bounce_kernels import continue_path, end_path, end_unresolved
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


@inlined
def _escape(ledger, escapes, sides, b, g, w, d, e):
    """Path ``g`` leaves the relief along ``d`` after order b − 1 with weight ``w``: reflected
    if it leaves on the incidence's side, else transmitted; listed in ``escapes`` at slot
    ``e`` (direction flipped up if it falls). Returns the number of escapes listed."""
    dx, dy, dz = d
    down = dz < 0.0
    transmitted = down != sides.from_below
    cls = order_class(b - 1)
    end_path(ledger, g, TRANS_1 + cls if transmitted else cls, w)
    escapes.index[e] = g
    escapes.dx[e], escapes.dy[e] = dx, dy
    escapes.dz[e] = -dz if down else dz
    escapes.transmitted[e] = transmitted
    return e + 1


@compiled
def interface_step(
    b, limit, floor, live, w, walk, rays, facets, interface, roulette, sides, ledger, escapes, nxt
):
    """One step ``b`` of the paths through a dielectric interface (module docstring): returns
    (continuing paths m, escapes e).

    Arguments: step ``b``, interaction ``limit``, weight ``floor``, the live paths' global
    indices ``live`` and weights ``w``; ``walk`` (``engine.segments.WalkResult`` of the rays
    traced at this step), ``rays`` (``bounce_kernels.RayDirections``), ``facets``
    (``bounce_kernels.FacetPlanes``; its lift n·v0 + eps), ``interface`` (``Interface``),
    ``roulette`` (``Roulette``), ``sides`` (``PathSides``, updated), ``ledger``
    (``bounce_kernels.PathLedger``, written), ``escapes`` (``SideEscapes``, written) and
    ``nxt`` (``bounce_kernels.NextRays``, written)."""
    hs, prim, px, py, pz = walk
    dx, dy, dz, shared = rays
    nx, ny, nz, lift, hx, hy = facets
    eta2, k2, absorbing, eps = interface
    m = 0
    e = 0
    for i in range(len(live)):
        g = live[i]
        j = 0 if shared else i
        h = hs[i]
        leaves_down = h == MISSED and dz[j] < 0.0
        if b == 2 and ledger.status1[g] == SINGLE and not (h == ESCAPED or leaves_down):
            ledger.status1[g] = (
                MASKED if h == HIT else (RAY_UNRESOLVED if h == UNRESOLVED else RAY_MISSED)
            )
        if b >= 2 and (h == ESCAPED or leaves_down) and leaves_down == sides.inside[g]:
            e = _escape(ledger, escapes, sides, b, g, w[i], (dx[j], dy[j], dz[j]), e)
            continue
        if h != HIT:
            walk_failed = RAY_UNRESOLVED if h == UNRESOLVED else RAY_MISSED
            path_failed = PATH_UNRESOLVED if h == UNRESOLVED else PATH_MISSED
            end_unresolved(ledger, b, g, w[i], path_failed, walk_failed)
            continue
        if b > limit:
            end_path(ledger, g, CUT_BOUNCES, w[i])
            continue
        f = prim[i]
        a0, a1, a2 = nx[f], ny[f], nz[f]
        c = -(dx[j] * a0 + dy[j] * a1 + dz[j] * a2)
        inside = sides.inside[g]
        if c == 0.0 or (c < 0.0) != inside:  # met from the side the path is not on
            end_unresolved(ledger, b, g, w[i], PATH_UNRESOLVED, RAY_UNRESOLVED)
            continue
        ci = abs(c)
        rel2 = 1.0 / eta2 if inside else eta2  # (η_t/η_i)²
        fw = fresnel_real_scalar(ci, rel2, 0.0 if inside else k2)
        tir = not absorbing and (1.0 - ci * ci) >= rel2  # sin²θi ≥ (η_t/η_i)²: F = 1
        if tir:
            sides.tir[g] |= np.int8(1 << (min(b, 4) - 1))
        if absorbing or tir:
            reflect, wn = True, w[i] * fw  # fw = 1 at total internal reflection
        else:
            reflect = path_uniform(roulette.stream, roulette.ray0 + g, b) < fw
            wn = w[i]
        if b == 1:
            ledger.weight1[g] = wn
            ledger.status1[g] = SINGLE
        if reflect:
            ox = dx[j] + 2.0 * c * a0
            oy = dy[j] + 2.0 * c * a1
            oz = dz[j] + 2.0 * c * a2
        else:
            s = 1.0 if c > 0.0 else -1.0  # n_s = s·n faces the arriving ray
            r = 1.0 / math.sqrt(rel2)
            ct = math.sqrt(max(1.0 - r * r * (1.0 - ci * ci), 0.0))
            k = (r * ci - ct) * s
            ox = r * dx[j] + k * a0
            oy = r * dy[j] + k * a1
            oz = r * dz[j] + k * a2
            sides.inside[g] = not inside
        if wn < floor:
            end_path(ledger, g, CUT_WEIGHT, wn)
            continue
        above = ox * a0 + oy * a1 + oz * a2 > 0.0
        side_offset = lift[f] if above else lift[f] - 2.0 * eps
        p, n, o = (px[i], py[i], pz[i]), (a0, a1, a2), (ox, oy, oz)
        continue_path(nxt, m, g, p, n, side_offset, (hx, hy), o, wn)
        m += 1
    return m, e

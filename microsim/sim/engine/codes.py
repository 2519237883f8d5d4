"""Status and class codes shared by the kernels, as compile-time constants: the walk's ray
status (``tracer.HIT`` …), the first-bounce ledger classes (``paths.SINGLE`` …) and the
terminal classes of a bounce chain (``bounces.TERMINAL``); ``tracer``/``paths``/``bounces``
assert they agree."""

from __future__ import annotations

from microsim.jit import compiled

# tracer status codes (``tracer.HIT`` ...) and ledger classes (``paths.SINGLE`` ...),
# repeated here as compile-time constants; ``paths``/``tracer`` assert they agree
HIT, ESCAPED, UNRESOLVED, MISSED = 0, 1, 2, 3


SINGLE, MASKED, DOWNWARD, RAY_UNRESOLVED, RAY_MISSED = 0, 1, 2, 3, 4


# --- scattering orders (``bounces``): paths followed beyond the first bounce ----------------
# terminal classes of a path (``bounces.TERMINAL``): escaped after order 1, 2, 3, >= 4; cut
# off by the bounce limit; cut off by the weight floor; unresolved; missed
ESC_1, ESC_2, ESC_3, ESC_4UP, CUT_BOUNCES, CUT_WEIGHT, PATH_UNRESOLVED, PATH_MISSED = range(8)


N_TERMINAL = 8
# a dielectric interface's paths (``dielectric``) add: transmitted (left on the side opposite
# the incidence) after order 1, 2, 3, >= 4
TRANS_1, TRANS_2, TRANS_3, TRANS_4UP = range(N_TERMINAL, N_TERMINAL + 4)
N_TERMINAL_DIELECTRIC = N_TERMINAL + 4


@compiled
def order_class(order):
    """Terminal class ESC_1 … ESC_4UP of a path escaping after ``order`` bounces."""
    return min(order, 4) - 1

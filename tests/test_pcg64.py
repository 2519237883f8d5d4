"""The compiled PCG64 stream (``sim.pcg64``) draws NumPy's numbers bit for bit, so the rays of
every run stay those ``Generator(PCG64).random`` gave them."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from microsim.sim import pcg64
from microsim.sim.streams import BLOCK, block_uniforms


def _numpy_draws(state: dict, position: int, n: int) -> np.ndarray:
    g = np.random.Generator(np.random.PCG64())
    g.bit_generator.state = state
    g.bit_generator.advance(position)
    return g.random(n)


@settings(max_examples=60, deadline=None)
@given(
    seed=st.lists(st.integers(0, 2**32 - 1), min_size=1, max_size=3),
    position=st.one_of(st.integers(0, 10**6), st.integers(0, 2**62)),
    n=st.one_of(st.integers(0, 9), st.integers(10, 5000)),
)
def test_fill_uniforms_is_numpys_random_from_any_position(seed, position, n):
    """Any seed, any position (the jump by squaring) and any length, short arrays included
    (some of the four runs empty): the same doubles as NumPy's, bit for bit."""
    state = np.random.PCG64(np.random.SeedSequence(seed)).state
    out = np.full(n, np.nan)
    pcg64.fill_uniforms(pcg64.stream_of(state), position, out)
    want = _numpy_draws(state, position, n)
    assert np.array_equal(out.view(np.uint64), want.view(np.uint64))


def test_block_uniforms_are_the_blocks_slots_of_the_keyed_stream():
    """Block b's numbers are [b·k·BLOCK, (b + 1)·k·BLOCK) of the stream seeded with the key,
    consecutive blocks follow one another, and ``skip`` starts further into the slot."""
    key = (7, 2, 1)
    state = np.random.PCG64(np.random.SeedSequence(list(key))).state
    out = np.empty(3 * 2 * BLOCK)
    block_uniforms(key, 5, 2, out)
    assert np.array_equal(out, _numpy_draws(state, 5 * 2 * BLOCK, len(out)))
    part = np.empty(100)
    block_uniforms(key, 4, 3, part, skip=2 * BLOCK)
    assert np.array_equal(part, _numpy_draws(state, 4 * 3 * BLOCK + 2 * BLOCK, 100))

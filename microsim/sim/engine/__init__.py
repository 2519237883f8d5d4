"""The ray engine's compiled kernels (numba, ``nogil``): the per-ray bookkeeping between
Embree calls of ``tracer``'s periodic walk and of the primary/masking passes of ``paths``.

Modules: ``codes`` (status and class codes), ``segments`` (one segment of the periodic walk),
``horizon`` (masking rays cleared without tracing), ``facets`` (the facets' normals and
planes, stored or derived from a heightfield's heights), ``primary`` (primary hits to ledger
classes and masking rays); their compile options are ``microsim.jit``'s. The estimator's
kernels sit beside their callers: ``sim.origin_kernels``, ``sim.ray_bins``,
``sim.fresnel_kernels``, ``sim.vgroove_kernels``, ``sim.bounce_kernels``, ``sim.tally_kernels``;
the portable arithmetic of bins (``microsim.bin_kernels``, ``microsim.trig``) is core.
"""

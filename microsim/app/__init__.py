"""The application, the top layer: scene files (``scene``), ``microsim run``/``report``
(``runner``), sweeps (``sweep``), the benchmarks (``bench``, ``bench_methods``, ``bench_peer``,
``wave_bench``), the pyvista views (``view``) and the command line (``cli``).

Layer: "app" (with ``microsim.testing``); it may import every lower layer. Nothing is imported
here: ``microsim.app.cli`` and the others are imported where they are used."""

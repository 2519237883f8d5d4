"""microsim — ray-traced explicit-integral microfacet BRDFs checked against closed forms.

Conventions (docs/design.md): local frame with the macro normal +z; every direction
is a unit vector pointing away from the surface (`wi` to the light, `wo` to the viewer);
θ from +z, φ from +x; public angles in degrees, internal in radians; BRDFs in sr⁻¹.

    import microsim
    result = microsim.simulate(surface, "aluminium", theta_i=[0, 30, 60, 80], rays=10**6)
"""

__version__ = "0.1.0"

__all__ = ["Bins", "Result", "simulate", "__version__"]


def __getattr__(name: str):
    """``microsim.simulate``, ``microsim.Bins``, ``microsim.Result`` on first use (PEP 562): the
    pytest plugin (``microsim.testing.plugin``, loaded by every pytest run where microsim is
    installed) then does not import the simulator and SciPy until a test needs them."""
    if name in ("Bins", "Result", "simulate"):
        from . import sim

        return getattr(sim, name)
    raise AttributeError(f"module 'microsim' has no attribute {name!r}")

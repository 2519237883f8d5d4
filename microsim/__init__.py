"""microsim — ray-traced explicit-integral microfacet BRDFs checked against closed forms.

Conventions (docs/design.md): local frame with the macro normal +z; every direction
is a unit vector pointing away from the surface (`wi` to the light, `wo` to the viewer);
θ from +z, φ from +x; public angles in degrees, internal in radians; BRDFs in sr⁻¹.

    import microsim
    result = microsim.simulate(surface, "aluminium", theta_i=[0, 30, 60, 80], rays=10**6)
"""

__version__ = "0.1.0"

from .sim import Bins, Result, simulate  # noqa: E402,F401

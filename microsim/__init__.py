"""microsim — ray-traced explicit-integral microfacet BRDFs checked against closed forms.

Conventions (see ../shared/DESIGN.md): local frame with the macro normal +z; every direction
is a unit vector pointing away from the surface (`wi` to the light, `wo` to the viewer);
θ from +z, φ from +x; public angles in degrees, internal in radians; BRDFs in sr⁻¹.
"""

__version__ = "0.1.0"

"""Closed-form microfacet models of the four papers (see docs/design.md).

from microsim import analytic as an
an.fresnel(cos_theta, material); an.Beckmann(m); an.torrance_sparrow(wi, wo, ndf, ...)
an.TorranceSparrow(an.GGX(0.3), an.Smith(correlated=True)).f(wi, wo)   # model objects
"""

from .anisotropic import *  # noqa: F401,F403
from .brdf import *  # noqa: F401,F403
from .edwards import *  # noqa: F401,F403
from .empirical import *  # noqa: F401,F403
from .energy_compensation import *  # noqa: F401,F403
from .fresnel import *  # noqa: F401,F403
from .low import *  # noqa: F401,F403
from .masking import *  # noqa: F401,F403
from .models import *  # noqa: F401,F403
from .ndf import *  # noqa: F401,F403
from .random_walk import *  # noqa: F401,F403
from .shadowing import *  # noqa: F401,F403

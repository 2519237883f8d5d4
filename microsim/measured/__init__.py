"""Measured BRDFs: tables of bin-averaged BRDF values over incidences (what microsim measures,
``table.BRDFTable``), their evaluation at any direction pair, and the formats renderers and
fitting tools read and write."""

from .merl import *  # noqa: F401,F403
from .rgl import *  # noqa: F401,F403
from .spectral import *  # noqa: F401,F403
from .table import *  # noqa: F401,F403

"""Incidences as outputs name them: a verdict, a chart panel or a table row belongs to one
incidence (θi, φi). A run with one incidence azimuth names its incidences by θi alone, as
every isotropic scene does; a run with several names each by θi and φi."""

from __future__ import annotations

from collections.abc import Iterable, Mapping

__all__ = ["key", "several_azimuths", "label", "where", "grouped"]


def key(v: Mapping) -> tuple[float, float]:
    """(θi, φi) of a verdict or incidence record (degrees; φi 0 when it records none)."""
    return float(v["theta_i"]), float(v.get("phi_i", 0.0))


def several_azimuths(records: Iterable[Mapping] | Iterable[float]) -> bool:
    """Whether the verdicts/records (or azimuths, degrees) hold more than one φi."""
    phis = {float(r) if isinstance(r, (int, float)) else key(r)[1] for r in records}
    return len(phis) > 1


def label(theta: float, phi: float, with_phi: bool, symbol: bool = True) -> str:
    """ "θi = 60°" (``symbol``) or "60°", with ", φi = 30°" / " φi 30°" when ``with_phi``."""
    if symbol:
        return f"θi = {theta:g}°" + (f", φi = {phi:g}°" if with_phi else "")
    return f"{theta:g}°" + (f" φi {phi:g}°" if with_phi else "")


def where(records: Iterable[Mapping], with_phi: bool) -> str:
    """The incidences of ``records`` as a list: "30°, 80°" or "30° φi 0°, 80° φi 90°"."""
    return ", ".join(label(*key(v), with_phi, symbol=False) for v in records)


def grouped(records: Iterable[Mapping], sep: str = ", ") -> str:
    """The incidences of ``records`` by azimuth, for the outputs of a run with several φi:
    "0, 80° at φi 0, 90°" (the same θi at each φi listed), else "30, 80° at φi 0° and
    80° at φi 90°"; ``sep`` joins the angles (", " or ",")."""
    by: dict[float, list[float]] = {}
    for v in records:
        t, p = key(v)
        by.setdefault(p, []).append(t)

    def angles(xs) -> str:
        return sep.join(f"{x:g}" for x in xs) + "°"

    lists = list(by.values())
    if all(x == lists[0] for x in lists):
        return f"{angles(lists[0])} at φi {angles(by)}"
    return " and ".join(f"{angles(ts)} at φi {p:g}°" for p, ts in by.items())

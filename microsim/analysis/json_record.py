"""``JsonRecord``: a frozen record that is also the read-only dict of one JSON object (of
verdicts.json, meta.json, methods.json, a sweep's summary), and ``MapOf``, how a record names
its nested objects. Every such record of the project derives from it."""

from __future__ import annotations

from dataclasses import MISSING, dataclass
from dataclasses import fields as dataclass_fields
from typing import ClassVar, Mapping

from microsim.sim.result import FrozenDict, FrozenList

__all__ = ["JsonRecord", "MapOf", "read_nested"]


@dataclass(frozen=True)
class MapOf:
    """A ``_nested`` entry: a JSON object of name → ``record``."""

    record: type


@dataclass(frozen=True, eq=False)
class JsonRecord(FrozenDict):
    """A frozen record of one JSON object: its fields by attribute and, as a read-only dict,
    the object. Nested objects are records too (``_nested``: field → record class, or
    ``MapOf`` one; a list of objects reads as a read-only list of records), however the
    record was made.

    Made directly, the dict holds the fields in declaration order, leaving out those named in
    ``OMITTED_IF_NONE`` when None. Read with ``from_json``, the dict is the object as read —
    its order, and keys of no field — so it is written back identically; a field the object
    lacks (an older file) reads as its ``OLDER_DEFAULTS`` value, else its default, else None."""

    _nested: ClassVar[Mapping[str, object]] = {}
    OMITTED_IF_NONE: ClassVar[tuple[str, ...]] = ()
    OLDER_DEFAULTS: ClassVar[Mapping] = {}

    def __post_init__(self) -> None:
        for name, kind in self._nested.items():
            object.__setattr__(self, name, read_nested(kind, getattr(self, name)))
        for f in dataclass_fields(self):
            value = getattr(self, f.name)
            if value is not None or f.name not in self.OMITTED_IF_NONE:
                dict.__setitem__(self, f.name, value)

    def __reduce__(self):
        return (_restore, (type(self), dict(self)))

    @classmethod
    def from_json(cls, d: Mapping):
        """The record of JSON object ``d`` (a record of this class as it is)."""
        if isinstance(d, cls):
            return d
        fields = dataclass_fields(cls)
        rec = cls(**{f.name: d[f.name] if f.name in d else _missing(cls, f) for f in fields})
        names = {f.name for f in fields}
        dict.clear(rec)  # the object as read, in its own order
        dict.update(rec, ((k, getattr(rec, k) if k in names else v) for k, v in d.items()))
        return rec


def _missing(cls, f):
    """What field ``f`` of ``cls`` reads as when the object lacks it."""
    if f.name in cls.OLDER_DEFAULTS:
        return cls.OLDER_DEFAULTS[f.name]
    if f.default is not MISSING:
        return f.default
    if f.default_factory is not MISSING:
        return f.default_factory()
    return None


def _restore(cls, d: dict):
    """A pickled or copied record rebuilt from its dict."""
    return cls.from_json(d)


def read_nested(kind, value):
    """``value`` as ``kind`` says: a record (a list of them: a read-only list), ``MapOf`` a
    read-only dict of name → record; no ``kind``, or None, as it is."""
    if kind is None or value is None:
        return value
    if isinstance(kind, MapOf):
        return FrozenDict({k: kind.record.from_json(v) for k, v in value.items()})
    if isinstance(value, Mapping):
        return kind.from_json(value)
    return FrozenList(kind.from_json(v) for v in value)

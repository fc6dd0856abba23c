"""MPEG-I haptics (ISO/IEC 23090-31) interchange format, JSON form (``.hjif``): data
structures, strict parsing and writing.

The structure follows what MPEG's reference software reads and writes (its ``IOJson``
reader/writer), not only the standard's prose:

- root: ``version`` (``"2023"``), ``profile`` (``"Main"`` / ``"Simple Parametric"``),
  ``level`` (1 or 2), ``date``, ``description``, ``timescale`` (ticks per second; the
  reference encoder writes 1000, and 1000 is assumed when absent), ``avatars``,
  ``perceptions``, ``syncs``;
- perception: ``id``, ``avatar_id``, ``description``, ``perception_modality``,
  optional ``priority``, ``unit_exponent`` (default -3), ``perception_unit_exponent``
  (default 0), ``reference_devices``, ``effect_library``, ``effect_semantic_scheme``,
  ``channels``;
- channel: ``id``, ``description``, ``gain``, ``mixing_coefficient``,
  ``body_part_mask``, ``bands``, optional ``reference_device_id``, ``frequency_sampling``,
  ``sample_count``, ``direction``, ``actuator_resolution``, ``body_part_target``,
  ``actuator_target``, ``vertices``, ``priority``;
- band: ``band_type`` (``VectorialWave``, ``Transient``, ``Curve``, ``WaveletWave``),
  ``lower_frequency_limit`` / ``upper_frequency_limit`` (integers, Hz), ``effects``,
  ``curve_type`` (Curve bands), ``block_length`` (Wavelet bands), ``priority``;
- effect: ``effect_type`` (``Basis``, ``Reference``, ``Composite``), ``position``
  (ticks), ``id`` (Reference effects: the library effect), ``phase`` (rad),
  ``base_signal`` (``Sine``, ``Square``, ``Triangle``, ``SawToothUp``, ``SawToothDown``),
  ``keyframes``, ``semantic_keywords``, ``wavelet_stream`` (base64, Wavelet bands);
- keyframe: ``relative_position`` (ticks from the effect's position),
  ``amplitude_modulation`` (-1..1), ``frequency_modulation`` (Hz), each optional.

Quirks of real files that the parser accepts: the modality spellings the reference
reader maps (``"Vibration"`` = Vibrotactile, ``"Kinesthetic"`` = Force, ``"Texture"`` =
Vibrotactile Texture); ``"Other"`` perceptions (the reference encoder labels every
AHAP/IVS/WAV input so); a ``date`` in the encoder's local ``"YYYY-MM-DD hh:mm:ss"`` form;
integer or real ``frequency_modulation`` (the reference reader keeps only integers, so the
SDK writes integers); ``timescale`` absent.

Every problem raises :class:`~hapticsdk.errors.FormatError` whose ``field`` is the JSON
path of the offending value (``perceptions[0].channels[1].bands[0].effects[3].keyframes[2]``).
Reading is bounded: files above :data:`MAX_FILE_BYTES` and JSON nested deeper than
:data:`MAX_DEPTH` are refused before they are parsed; text must be UTF-8.
"""

from __future__ import annotations

import copy
import json
import math
import os
from dataclasses import dataclass, field
from typing import Any, Mapping

from ..checks import finite_float
from ..errors import FormatError, ValidationError
from ..schemas_io import json_depth
from .hjif_versions import VersionReport, normalise

#: largest ``.hjif`` accepted (bytes). Real vibrotactile files are kilobytes to a few
#: megabytes (wavelet streams included); 32 MiB leaves room and bounds memory.
MAX_FILE_BYTES = 32 * 1024 * 1024
#: deepest JSON nesting accepted; a valid file nests 11 levels (root > perceptions >
#: perception > channels > channel > bands > band > effects > effect > keyframes > keyframe).
MAX_DEPTH = 32
#: timescale assumed when a file has none (the reference software's default), ticks/s
DEFAULT_TIMESCALE = 1000
#: perception defaults of the reference software
DEFAULT_UNIT_EXPONENT = -3
DEFAULT_PERCEPTION_UNIT_EXPONENT = 0

#: canonical modality names, and the spellings real files use for them
MODALITIES = ("Other", "Pressure", "Acceleration", "Velocity", "Position", "Temperature",
              "Vibrotactile", "Water", "Wind", "Force", "Vibrotactile Texture", "Stiffness",
              "Friction", "Electrotactile")
MODALITY_ALIASES = {"Vibration": "Vibrotactile", "Kinesthetic": "Force", "Texture": "Vibrotactile Texture"}
BAND_TYPES = ("WaveletWave", "VectorialWave", "Curve", "Transient")
CURVE_TYPES = ("Unknown", "Cubic", "Linear", "Akima", "Bezier", "Bspline")
EFFECT_TYPES = ("Basis", "Reference", "Composite")
BASE_SIGNALS = ("Sine", "Square", "Triangle", "SawToothUp", "SawToothDown")
AVATAR_TYPES = ("Vibration", "Pressure", "Temperature", "Custom")
ACTUATOR_TYPES = ("Unknown", "LRA", "VCA", "ERM", "Piezo")
PROFILES = ("Main", "Simple Parametric")

#: a valid phase lies in [-2 pi, 2 pi] (the binary format quantises |phase| <= 6.28318)
MAX_PHASE = 2 * math.pi + 1e-6


# ----------------------------------------------------------------------------- data
@dataclass
class Keyframe:
    """One keyframe. ``relative_position`` in ticks from the effect's position;
    ``amplitude_modulation`` -1..1; ``frequency_modulation`` in Hz. Each may be ``None``."""

    relative_position: int | None = None
    amplitude_modulation: float | None = None
    frequency_modulation: float | None = None

    def to_dict(self) -> dict[str, Any]:
        """The keyframe in .hjif JSON form (only the fields that are set)."""
        d: dict[str, Any] = {}
        if self.relative_position is not None:
            d["relative_position"] = self.relative_position
        if self.amplitude_modulation is not None:
            d["amplitude_modulation"] = self.amplitude_modulation
        if self.frequency_modulation is not None:
            d["frequency_modulation"] = self.frequency_modulation
        return d


@dataclass
class Effect:
    """A Basis effect (keyframes and a base signal), a Reference to a library effect
    (``id``), or a Composite. ``position`` in ticks; ``phase`` in rad."""

    effect_type: str
    position: int
    id: int | None = None
    phase: float | None = None
    base_signal: str | None = None
    keyframes: list[Keyframe] = field(default_factory=list)
    semantic_keywords: str | None = None
    wavelet_stream: str | None = None
    path: str = ""

    def to_dict(self, *, library: bool = False) -> dict[str, Any]:
        """The effect in .hjif JSON form; ``library=True`` for an entry of a perception's
        effect library (always with an ``id``).
        """
        d: dict[str, Any] = {"effect_type": self.effect_type}
        if library or (self.id is not None and self.effect_type == "Reference"):
            d["id"] = self.id if self.id is not None else 0
        d["position"] = self.position
        if self.semantic_keywords is not None:
            d["semantic_keywords"] = self.semantic_keywords
        if self.effect_type != "Reference":
            if self.phase is not None:
                d["phase"] = self.phase
            if self.base_signal is not None:
                d["base_signal"] = self.base_signal
            if self.wavelet_stream is not None:
                d["wavelet_stream"] = self.wavelet_stream
            else:
                d["keyframes"] = [k.to_dict() for k in self.keyframes]
        return d


@dataclass
class Band:
    """A band of a channel: its type, frequency limits (Hz, integers) and effects."""

    band_type: str
    lower_frequency_limit: int
    upper_frequency_limit: int
    effects: list[Effect] = field(default_factory=list)
    curve_type: str | None = None
    block_length: int | None = None
    priority: int | None = None
    path: str = ""

    def to_dict(self) -> dict[str, Any]:
        """The band in .hjif JSON form (only the optional fields that are set)."""
        d: dict[str, Any] = {"band_type": self.band_type}
        if self.priority is not None:
            d["priority"] = self.priority
        if self.curve_type is not None:
            d["curve_type"] = self.curve_type
        if self.block_length is not None:
            d["block_length"] = self.block_length
        d["lower_frequency_limit"] = self.lower_frequency_limit
        d["upper_frequency_limit"] = self.upper_frequency_limit
        d["effects"] = [e.to_dict() for e in self.effects]
        return d


@dataclass
class Channel:
    """A channel of a perception: gain, mixing coefficient, body-part mask, bands.
    ``extra`` keeps the optional spatial fields (direction, targets, vertices) as read."""

    id: int
    description: str
    gain: float
    mixing_coefficient: float
    body_part_mask: int
    bands: list[Band] = field(default_factory=list)
    reference_device_id: int | None = None
    frequency_sampling: int | None = None
    sample_count: int | None = None
    priority: int | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    path: str = ""

    def to_dict(self) -> dict[str, Any]:
        """The channel in .hjif JSON form (only the optional fields that are set)."""
        d: dict[str, Any] = {"id": self.id, "description": self.description, "gain": self.gain,
                             "mixing_coefficient": self.mixing_coefficient,
                             "body_part_mask": self.body_part_mask}
        for k in ("priority", "reference_device_id", "frequency_sampling", "sample_count"):
            v = getattr(self, k)
            if v is not None:
                d[k] = v
        d.update(self.extra)
        d["bands"] = [b.to_dict() for b in self.bands]
        return d


@dataclass
class ReferenceDevice:
    """A device the content was designed for (``name``, optional ``type`` and ranges)."""

    id: int
    name: str
    extra: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """The reference device in .hjif JSON form (id, name and its other fields as read).
        """
        return {"id": self.id, "name": self.name, **self.extra}


@dataclass
class Perception:
    """One perception: a modality with channels, an effect library and unit exponents.

    ``perception_modality`` is the canonical name; ``modality_as_written`` the spelling
    of the file (e.g. ``"Vibration"``).
    """

    id: int
    avatar_id: int
    description: str
    perception_modality: str
    channels: list[Channel] = field(default_factory=list)
    effect_library: list[Effect] = field(default_factory=list)
    unit_exponent: int | None = None
    perception_unit_exponent: int | None = None
    reference_devices: list[ReferenceDevice] = field(default_factory=list)
    priority: int | None = None
    effect_semantic_scheme: str | None = None
    modality_as_written: str = ""
    path: str = ""

    @property
    def unit_exponent_or_default(self) -> int:
        """The perception's unit exponent, or the format's default when the file gives none.
        """
        return DEFAULT_UNIT_EXPONENT if self.unit_exponent is None else self.unit_exponent

    @property
    def perception_unit_exponent_or_default(self) -> int:
        """The perception unit exponent, or the format's default when the file gives none.
        """
        return (DEFAULT_PERCEPTION_UNIT_EXPONENT if self.perception_unit_exponent is None
                else self.perception_unit_exponent)

    def library_effect(self, effect_id: int) -> Effect | None:
        """The effect library entry with ``effect_id``, or ``None`` (an index built on
        first use and rebuilt when the library's length changes: one lookup costs O(1),
        not O(library), so references cost linear time in the file's size)."""
        idx = self.__dict__.get("_library_index")
        if idx is None or idx[0] != len(self.effect_library):
            table: dict[int | None, Effect] = {}
            for e in self.effect_library:
                table.setdefault(e.id, e)
            idx = (len(self.effect_library), table)
            self.__dict__["_library_index"] = idx
        return idx[1].get(effect_id)

    def reference_device(self, device_id: int | None) -> ReferenceDevice | None:
        """The reference device with ``device_id``, or ``None``."""
        for d in self.reference_devices:
            if d.id == device_id:
                return d
        return None

    def to_dict(self) -> dict[str, Any]:
        """The perception in .hjif JSON form (only the optional fields that are set)."""
        d: dict[str, Any] = {"id": self.id, "avatar_id": self.avatar_id, "description": self.description,
                             "perception_modality": self.perception_modality}
        if self.priority is not None:
            d["priority"] = self.priority
        if self.unit_exponent is not None:
            d["unit_exponent"] = self.unit_exponent
        if self.perception_unit_exponent is not None:
            d["perception_unit_exponent"] = self.perception_unit_exponent
        d["reference_devices"] = [r.to_dict() for r in self.reference_devices]
        d["effect_library"] = [e.to_dict(library=True) for e in self.effect_library]
        if self.effect_semantic_scheme is not None:
            d["effect_semantic_scheme"] = self.effect_semantic_scheme
        d["channels"] = [c.to_dict() for c in self.channels]
        return d


@dataclass
class Avatar:
    id: int
    lod: int
    type: str
    mesh: str | None = None

    def to_dict(self) -> dict[str, Any]:
        """The avatar in .hjif JSON form."""
        d: dict[str, Any] = {"id": self.id, "lod": self.lod, "type": self.type}
        if self.mesh is not None:
            d["mesh"] = self.mesh
        return d


@dataclass
class Sync:
    timestamp: int
    timescale: int | None = None

    def to_dict(self) -> dict[str, Any]:
        """The sync point in .hjif JSON form."""
        d: dict[str, Any] = {"timestamp": self.timestamp}
        if self.timescale is not None:
            d["timescale"] = self.timescale
        return d


@dataclass
class HapticFile:
    """A whole ``.hjif`` document. ``timescale`` in ticks per second (``None``: absent
    from the file, :data:`DEFAULT_TIMESCALE` applies)."""

    version: str
    profile: str
    level: int
    date: str
    description: str
    perceptions: list[Perception]
    avatars: list[Avatar] = field(default_factory=list)
    syncs: list[Sync] = field(default_factory=list)
    timescale: int | None = DEFAULT_TIMESCALE
    #: what :func:`~hapticsdk.interop.hjif_versions.normalise` recognised and changed
    #: (``None`` for a document built in code)
    format_version: VersionReport | None = None

    @property
    def ticks_per_second(self) -> int:
        """Time ticks per second of the file (its timescale, or the format's default)."""
        return DEFAULT_TIMESCALE if self.timescale is None else self.timescale

    def to_dict(self) -> dict[str, Any]:
        """The whole file in .hjif JSON form."""
        d: dict[str, Any] = {"version": self.version, "profile": self.profile, "level": self.level,
                             "date": self.date, "description": self.description}
        if self.timescale is not None:
            d["timescale"] = self.timescale
        d["avatars"] = [a.to_dict() for a in self.avatars]
        d["perceptions"] = [p.to_dict() for p in self.perceptions]
        d["syncs"] = [s.to_dict() for s in self.syncs]
        return d

    def to_json(self, *, indent: int | None = 1) -> str:
        """JSON text (``allow_nan=False``: a NaN can never be written)."""
        return json.dumps(self.to_dict(), indent=indent, allow_nan=False, ensure_ascii=False) + "\n"


# ----------------------------------------------------------------------------- reading
def read_hjif(path: str | os.PathLike[str], *, max_bytes: int = MAX_FILE_BYTES) -> HapticFile:
    """Read, bound-check and parse a ``.hjif`` file.

    Raises:
        FormatError: ``field`` is the file name for size / encoding / JSON syntax
            problems, else the JSON path of the offending value.
    """
    name, data = read_bounded(path, max_bytes=max_bytes, kind=".hjif")
    return parse_hjif_bytes(data, source=name)


def read_bounded(path: str | os.PathLike[str], *, max_bytes: int, kind: str) -> tuple[str, bytes]:
    """``(name, bytes)`` of a regular file of at most ``max_bytes`` bytes: refused from its
    size before reading, and never more than ``max_bytes + 1`` bytes read (a file that
    grows while being read is refused too). ``kind`` names the format in the message."""
    from ..argcheck import file_path
    try:
        p = file_path(path, "path")
    except ValidationError as exc:
        raise FormatError(exc.reason, field="path") from None
    name = str(p)
    try:
        size = p.stat().st_size
    except OSError as exc:
        raise FormatError(f"cannot read: {exc.strerror or exc}", field=name) from None
    if not p.is_file():
        raise FormatError("not a regular file", field=name)
    if size > max_bytes:
        raise FormatError(f"file is {size} bytes, above the {max_bytes}-byte cap for {kind} files",
                          field=name)
    try:
        with p.open("rb") as fh:
            data = fh.read(max_bytes + 1)
    except OSError as exc:
        raise FormatError(f"cannot read: {exc.strerror or exc}", field=name) from None
    if len(data) > max_bytes:  # grew while being read
        raise FormatError(f"file is above the {max_bytes}-byte cap for {kind} files", field=name)
    return name, data


def parse_hjif_bytes(data: bytes, *, source: str = "hjif") -> HapticFile:
    """Parse the bytes of a ``.hjif`` document (UTF-8, optional BOM)."""
    return parse_hjif_text(utf8_text(data, source=source), source=source)


def utf8_text(data: bytes, *, source: str) -> str:
    """``data`` decoded as UTF-8 (optional BOM), or a :class:`FormatError` naming the byte."""
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise FormatError(f"not UTF-8 text (byte {exc.start}: {data[exc.start:exc.start + 1]!r})",
                          field=source) from None


def _no_constants(name: str) -> Any:
    raise ValueError(f"{name} is not valid JSON")


class _DuplicateKey(ValueError):
    pass


def _pairs(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in pairs:
        if k in out:
            raise _DuplicateKey(f"duplicate key {k!r}")
        out[k] = v
    return out


def parse_hjif_text(text: str, *, source: str = "hjif") -> HapticFile:
    """Parse ``.hjif`` JSON text (nesting checked before the JSON parser runs)."""
    return _parse_any(load_json(text, source=source))


def load_json(text: str, *, source: str, unique_keys: bool = True) -> Any:
    """Decode JSON ``text`` within :data:`MAX_DEPTH` levels (counted before the parser
    runs); NaN/Infinity and (with ``unique_keys``) duplicate keys are refused. Every
    problem is a :class:`FormatError` with ``field=source``."""
    depth = json_depth(text)
    if depth > MAX_DEPTH:
        raise FormatError(f"JSON nested {depth} levels deep, above the limit of {MAX_DEPTH}", field=source)
    try:
        return json.loads(text, parse_constant=_no_constants, object_pairs_hook=_pairs if unique_keys else None)
    except _DuplicateKey as exc:
        raise FormatError(str(exc), field=source) from None
    except json.JSONDecodeError as exc:
        raise FormatError(f"invalid JSON at line {exc.lineno} column {exc.colno}: {exc.msg}",
                          field=source) from None
    except (ValueError, RecursionError) as exc:
        raise FormatError(f"invalid JSON: {exc}", field=source) from None


# -- typed field access -------------------------------------------------------------------
_MISSING = object()


def _type_name(v: Any) -> str:
    if v is None:
        return "null"
    if isinstance(v, bool):
        return "boolean"
    if isinstance(v, int):
        return "integer"
    if isinstance(v, float):
        return "number"
    if isinstance(v, str):
        return "string"
    if isinstance(v, list):
        return "array"
    if isinstance(v, dict):
        return "object"
    return type(v).__name__


def _join(path: str, key: str) -> str:
    return f"{path}.{key}" if path else key


def _get(obj: Mapping[str, Any], key: str, path: str, kind: str, *, required: bool = True,
         default: Any = None) -> Any:
    v = obj.get(key, _MISSING)
    where = _join(path, key)
    if v is _MISSING:
        if required:
            raise FormatError(f"missing required field {key!r}", field=path or "$")
        return default
    ok = {"int": isinstance(v, int) and not isinstance(v, bool),
          "number": isinstance(v, (int, float)) and not isinstance(v, bool),
          "str": isinstance(v, str),
          "list": isinstance(v, list),
          "dict": isinstance(v, dict)}[kind]
    if not ok:
        want = {"int": "an integer", "number": "a number", "str": "a string", "list": "an array",
                "dict": "an object"}[kind]
        raise FormatError(f"must be {want}, got {_type_name(v)}", field=where)
    # (an int beyond the float range, which JSON can hold, is not finite either)
    if kind == "number" and finite_float(v) is None:
        raise FormatError("must be finite", field=where)
    return v


def _range(v: Any, path: str, lo: float | None = None, hi: float | None = None) -> Any:
    if v is None:
        return v
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        rng = f"[{lo if lo is not None else '-inf'}, {hi if hi is not None else 'inf'}]"
        raise FormatError(f"{v!r} outside {rng}", field=path)
    return v


def _enum(v: str, path: str, allowed: tuple[str, ...]) -> str:
    if v not in allowed:
        raise FormatError(f"unknown value {v!r}; expected one of {', '.join(allowed)}", field=path)
    return v


def _obj(v: Any, path: str) -> Mapping[str, Any]:
    if not isinstance(v, dict):
        raise FormatError(f"must be an object, got {_type_name(v)}", field=path)
    return v


# -- structure ----------------------------------------------------------------------------
def parse_hjif(doc: Any) -> HapticFile:
    """Build a :class:`HapticFile` from decoded JSON, checking every field (types,
    enumerations, ranges, keyframe order, effect references). Raises :class:`FormatError`
    naming the JSON path.

    Documents of every published shape are read: they are first normalised (on a copy) by
    :func:`~hapticsdk.interop.hjif_versions.normalise`, whose report becomes
    :attr:`HapticFile.format_version`."""
    return _parse_any(copy.deepcopy(doc))


def _parse_any(doc: Any) -> HapticFile:
    """Normalise ``doc`` (in place) and parse it."""
    doc, report = normalise(doc)
    hfile = _parse_current(doc)
    hfile.format_version = report
    return hfile


def _parse_current(doc: Any) -> HapticFile:
    root = _obj(doc, "$")
    version = _get(root, "version", "", "str")
    profile = _get(root, "profile", "", "str")
    level = _range(_get(root, "level", "", "int"), "level", 0, 255)
    date = _get(root, "date", "", "str")
    description = _get(root, "description", "", "str")
    # a uint32 as the file's other counts: times are divided by it (an int of 400 digits
    # overflowed float() there)
    timescale = _range(_get(root, "timescale", "", "int", required=False), "timescale", 1, 2 ** 32 - 1)
    avatars_raw = _get(root, "avatars", "", "list")
    perceptions_raw = _get(root, "perceptions", "", "list")
    syncs_raw = _get(root, "syncs", "", "list")
    if not perceptions_raw:
        raise FormatError("a haptic file needs at least one perception", field="perceptions")
    avatars = [_avatar(a, f"avatars[{i}]") for i, a in enumerate(avatars_raw)]
    perceptions = [_perception(p, f"perceptions[{i}]") for i, p in enumerate(perceptions_raw)]
    seen: set[int] = set()
    for p in perceptions:
        if p.id in seen:
            raise FormatError(f"perception id {p.id} is not unique", field=f"{p.path}.id")
        seen.add(p.id)
    syncs = []
    for i, s in enumerate(syncs_raw):
        path = f"syncs[{i}]"
        s = _obj(s, path)
        syncs.append(Sync(timestamp=_range(_get(s, "timestamp", path, "int"), f"{path}.timestamp", 0),
                          timescale=_range(_get(s, "timescale", path, "int", required=False),
                                           f"{path}.timescale", 1, 2 ** 32 - 1)))
    return HapticFile(version=version, profile=profile, level=level, date=date, description=description,
                      perceptions=perceptions, avatars=avatars, syncs=syncs, timescale=timescale)


def _avatar(a: Any, path: str) -> Avatar:
    a = _obj(a, path)
    return Avatar(id=_get(a, "id", path, "int"), lod=_get(a, "lod", path, "int"),
                  type=_enum(_get(a, "type", path, "str"), f"{path}.type", AVATAR_TYPES),
                  mesh=_get(a, "mesh", path, "str", required=False))


def _perception(p: Any, path: str) -> Perception:
    p = _obj(p, path)
    pid = _get(p, "id", path, "int")
    avatar_id = _get(p, "avatar_id", path, "int")
    description = _get(p, "description", path, "str")
    written = _get(p, "perception_modality", path, "str")
    modality = MODALITY_ALIASES.get(written, written)
    if modality not in MODALITIES:
        raise FormatError(f"unknown perception modality {written!r}; expected one of "
                          f"{', '.join(MODALITIES)} (or {', '.join(MODALITY_ALIASES)})",
                          field=f"{path}.perception_modality")
    channels_raw = _get(p, "channels", path, "list")
    library_raw = _get(p, "effect_library", path, "list")
    devices_raw = _get(p, "reference_devices", path, "list", required=False, default=[])
    perception = Perception(
        id=pid, avatar_id=avatar_id, description=description, perception_modality=modality,
        unit_exponent=_range(_get(p, "unit_exponent", path, "int", required=False), f"{path}.unit_exponent", -128, 127),
        perception_unit_exponent=_range(_get(p, "perception_unit_exponent", path, "int", required=False),
                                        f"{path}.perception_unit_exponent", -128, 127),
        priority=_get(p, "priority", path, "int", required=False),
        effect_semantic_scheme=_get(p, "effect_semantic_scheme", path, "str", required=False),
        modality_as_written=written, path=path)
    for i, d in enumerate(devices_raw):
        dpath = f"{path}.reference_devices[{i}]"
        d = _obj(d, dpath)
        extra: dict[str, Any] = {}
        for k, v in d.items():
            if k in ("id", "name"):
                continue
            if k == "type":
                extra[k] = _enum(_get(d, k, dpath, "str"), f"{dpath}.type", ACTUATOR_TYPES)
            elif k == "body_part_mask":
                extra[k] = _range(_get(d, k, dpath, "int"), f"{dpath}.{k}", 0, 2 ** 32 - 1)
            else:
                extra[k] = _range(_get(d, k, dpath, "number"), f"{dpath}.{k}", 0)
        perception.reference_devices.append(ReferenceDevice(id=_get(d, "id", dpath, "int"),
                                                            name=_get(d, "name", dpath, "str"), extra=extra))
    lib_ids: set[int] = set()
    for i, e in enumerate(library_raw):
        epath = f"{path}.effect_library[{i}]"
        eff = _effect(e, epath, band_type=None)
        if eff.id is None:
            raise FormatError("a library effect needs an 'id'", field=epath)
        if eff.id in lib_ids:
            raise FormatError(f"library effect id {eff.id} is not unique", field=f"{epath}.id")
        lib_ids.add(eff.id)
        perception.effect_library.append(eff)
    for e in perception.effect_library:  # a library effect may itself refer to another one
        if e.effect_type == "Reference" and e.id not in lib_ids:
            raise FormatError(f"effect id {e.id} is not in the effect library", field=f"{e.path}.id")
    chan_ids: set[int] = set()
    for i, c in enumerate(channels_raw):
        ch = _channel(c, f"{path}.channels[{i}]", perception)
        if ch.id in chan_ids:
            raise FormatError(f"channel id {ch.id} is not unique", field=f"{ch.path}.id")
        chan_ids.add(ch.id)
        perception.channels.append(ch)
    return perception


_CHANNEL_KNOWN = {"id", "description", "gain", "mixing_coefficient", "body_part_mask", "bands",
                  "reference_device_id", "frequency_sampling", "sample_count", "priority"}


def _channel(c: Any, path: str, perception: Perception) -> Channel:
    c = _obj(c, path)
    ch = Channel(id=_get(c, "id", path, "int"), description=_get(c, "description", path, "str"),
                 gain=_get(c, "gain", path, "number"),
                 mixing_coefficient=_range(_get(c, "mixing_coefficient", path, "number"),
                                           f"{path}.mixing_coefficient", 0),
                 body_part_mask=_range(_get(c, "body_part_mask", path, "int"), f"{path}.body_part_mask",
                                       0, 2 ** 32 - 1),
                 reference_device_id=_get(c, "reference_device_id", path, "int", required=False),
                 frequency_sampling=_range(_get(c, "frequency_sampling", path, "int", required=False),
                                           f"{path}.frequency_sampling", 0),
                 sample_count=_range(_get(c, "sample_count", path, "int", required=False),
                                     f"{path}.sample_count", 0),
                 priority=_get(c, "priority", path, "int", required=False), path=path)
    if ch.reference_device_id is not None and perception.reference_device(ch.reference_device_id) is None:
        raise FormatError(f"reference device {ch.reference_device_id} is not among the perception's "
                          "reference_devices", field=f"{path}.reference_device_id")
    for k, v in c.items():
        if k in _CHANNEL_KNOWN:
            continue
        if k in ("direction", "actuator_resolution"):
            _vector(v, f"{path}.{k}")
        elif k == "actuator_target":
            for j, t in enumerate(_get(c, k, path, "list")):
                _vector(t, f"{path}.{k}[{j}]")
        elif k in ("body_part_target", "vertices"):
            for j, t in enumerate(_get(c, k, path, "list")):
                want = str if k == "body_part_target" else int
                if not isinstance(t, want) or isinstance(t, bool):
                    raise FormatError(f"must be {'a string' if want is str else 'an integer'}, "
                                      f"got {_type_name(t)}", field=f"{path}.{k}[{j}]")
        ch.extra[k] = v
    for i, b in enumerate(_get(c, "bands", path, "list")):
        ch.bands.append(_band(b, f"{path}.bands[{i}]", perception))
    return ch


def _vector(v: Any, path: str) -> None:
    v = _obj(v, path)
    for axis in ("X", "Y", "Z"):
        _range(_get(v, axis, path, "int"), f"{path}.{axis}", -128, 127)


def _band(b: Any, path: str, perception: Perception) -> Band:
    b = _obj(b, path)
    band_type = _enum(_get(b, "band_type", path, "str"), f"{path}.band_type", BAND_TYPES)
    lo = _range(_get(b, "lower_frequency_limit", path, "int"), f"{path}.lower_frequency_limit", 0, 65535)
    hi = _range(_get(b, "upper_frequency_limit", path, "int"), f"{path}.upper_frequency_limit", 0, 65535)
    if hi < lo:
        raise FormatError(f"upper_frequency_limit {hi} < lower_frequency_limit {lo}",
                          field=f"{path}.upper_frequency_limit")
    curve = _get(b, "curve_type", path, "str", required=False)
    if curve is not None:
        _enum(curve, f"{path}.curve_type", CURVE_TYPES)
    block = _get(b, "block_length", path, "int", required=band_type == "WaveletWave")
    band = Band(band_type=band_type, lower_frequency_limit=lo, upper_frequency_limit=hi, curve_type=curve,
                block_length=_range(block, f"{path}.block_length", 1), priority=_get(b, "priority", path, "int",
                                                                                     required=False), path=path)
    for i, e in enumerate(_get(b, "effects", path, "list")):
        eff = _effect(e, f"{path}.effects[{i}]", band_type=band_type)
        if eff.effect_type == "Reference" and perception.library_effect(eff.id) is None:  # type: ignore[arg-type]
            raise FormatError(f"effect id {eff.id} is not in the perception's effect_library "
                              f"(ids {sorted(x.id for x in perception.effect_library if x.id is not None)})",
                              field=f"{eff.path}.id")
        band.effects.append(eff)
    return band


def _effect(e: Any, path: str, *, band_type: str | None) -> Effect:
    e = _obj(e, path)
    etype = _enum(_get(e, "effect_type", path, "str"), f"{path}.effect_type", EFFECT_TYPES)
    eff = Effect(effect_type=etype,
                 position=_range(_get(e, "position", path, "int"), f"{path}.position", 0, 2 ** 31 - 1),
                 id=_range(_get(e, "id", path, "int", required=etype == "Reference"), f"{path}.id", 0),
                 phase=_range(_get(e, "phase", path, "number", required=False), f"{path}.phase",
                              -MAX_PHASE, MAX_PHASE),
                 semantic_keywords=_get(e, "semantic_keywords", path, "str", required=False), path=path)
    bs = _get(e, "base_signal", path, "str", required=False)
    eff.base_signal = None if bs is None else _enum(bs, f"{path}.base_signal", BASE_SIGNALS)
    if band_type == "WaveletWave" and etype == "Basis":
        eff.wavelet_stream = _get(e, "wavelet_stream", path, "str")
    kfs = _get(e, "keyframes", path, "list", required=False, default=[])
    last = -1
    for i, k in enumerate(kfs):
        kpath = f"{path}.keyframes[{i}]"
        k = _obj(k, kpath)
        kf = Keyframe(
            relative_position=_range(_get(k, "relative_position", kpath, "int", required=False),
                                     f"{kpath}.relative_position", 0, 2 ** 31 - 1),
            amplitude_modulation=_range(_get(k, "amplitude_modulation", kpath, "number", required=False),
                                        f"{kpath}.amplitude_modulation", -1.0, 1.0),
            frequency_modulation=_range(_get(k, "frequency_modulation", kpath, "number", required=False),
                                        f"{kpath}.frequency_modulation", 0.0, 65535.0))
        pos = 0 if kf.relative_position is None else kf.relative_position
        if pos < last:
            raise FormatError(f"keyframes out of order: relative_position {pos} after {last}", field=kpath)
        last = pos
        eff.keyframes.append(kf)
    if band_type == "WaveletWave" and eff.keyframes:
        raise FormatError("effects of a WaveletWave band carry no keyframes", field=f"{path}.keyframes")
    return eff

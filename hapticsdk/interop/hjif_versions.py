"""Every published shape of the ``.hjif`` format, normalised to the current one.

MPEG's reference software (``MPEGGroup/HapticReferenceSoftware``) has published seven
releases of its JSON reader. What each one reads (learned from its ``IOJson`` reader at
each release tag; see ``docs/interop.md`` for the table):

=========  ==========  ==========================================================================
release    date        shape
=========  ==========  ==========================================================================
CRM0       2022-01     ``tracks``; bands ``"Wave"`` + ``encoding_modality``; ``window_length``
CRM1       2022-04     as CRM0 + ``curve_type``, ``frequency_sampling``, ``reference_device_id``
CRM2       2022-07     ``VectorialWave``/``WaveletWave``; ``effect_library``, ``effect_type``
                       (``Basis``/``Reference``/``Timeline``); still ``tracks``, ``window_length``
CRM3       2023-01     ``channels``; ``block_length`` (a real number, on every band);
                       ``mixing_weight``
CRM3.1/2   2023-05/11  + ``profile``, ``level``, ``timescale``, ``syncs``, effect ``semantic``
CRM4       2024-03     FDIS (``version`` "2023"): ``mixing_coefficient``, ``semantic_keywords``,
                       ``wavelet_stream``, ``priority``; ``block_length`` only on wavelet bands
=========  ==========  ==========================================================================

:func:`normalise` recognises the shape of a decoded document, rewrites it into the current
(FDIS) shape and returns a :class:`VersionReport` that lists every change by JSON path.
What is normalised, and how the reference reads it:

- renamed fields: ``tracks`` -> ``channels``, ``mixing_weight`` -> ``mixing_coefficient``,
  ``window_length`` -> ``block_length``, effect ``semantic`` -> ``semantic_keywords``,
  effect type ``Timeline`` -> ``Composite``; band type ``Wave`` with ``encoding_modality``
  ``Vectorial`` -> ``VectorialWave``, ``Wavelet``/``Quantized`` -> ``WaveletWave``;
- ``block_length`` on a band that is not a wavelet band (CRM3..CRM3.2 write ``0.0`` on
  every band): dropped; an integral real block length on a wavelet band becomes an integer;
- root fields the older readers did not know (``profile``, ``level``, ``syncs``) get the
  current defaults; Basis effects without ``effect_type`` (CRM0/CRM1) are Basis;
- keyframes out of order (``relative_position`` 65534 then 0, as decoded 16-bit positions
  give): the reference reader keeps file order and its synthesiser takes, for a time ``t``,
  the first keyframe *in file order* at or after ``t`` and the keyframe before *that one in
  file order*. A keyframe after a later-positioned one is therefore shadowed. The
  normaliser evaluates that reading at every keyframe position of the effect's span (the
  span ends at the last keyframe in file order, as the reference's length does) and writes
  the sorted keyframes that give the same amplitude and frequency: a step of the reading
  becomes two keyframes at the same position. Transient and Curve bands are sorted (stable):
  each transient keyframe is its own pulse, and the reference's curve synthesis offsets every
  keyframe by the first one;
- wavelet effects that carry keyframes and no ``wavelet_stream`` (before CRM4 the encoded
  wavelet coefficients were keyframes, which the reference synthesiser decodes first):
  reported and not played, as wavelet content of every version.

A document no release reads still fails in :func:`~hapticsdk.interop.hjif_model.parse_hjif`
with a :class:`~hapticsdk.errors.FormatError` naming the JSON path.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from ..checks import finite_float
from ..errors import FormatError
from .budget import MAX_REORDER_KEYFRAMES, ContentBudgetError

#: the shapes recognised, oldest first: (label, what identifies it)
RELEASES = (
    ("CRM0-CRM1 (2022)", "perceptions[].tracks, bands of type 'Wave' with encoding_modality, window_length"),
    ("CRM2 (2022-07)", "perceptions[].tracks, effect_library, window_length"),
    ("CRM3-CRM3.2 (2023)", "perceptions[].channels with mixing_weight, block_length on every band"),
    ("CRM4 / FDIS 2023 (2024-03)", "mixing_coefficient, block_length only on wavelet bands"),
)
#: the release whose shape the SDK reads natively and writes
CURRENT = RELEASES[-1][0]
#: relative positions at or above this come from a 16-bit field's top values (65534,
#: 65535): they are reported as sentinels when they come out of order
SENTINEL_MIN = 65534

_BAND_FROM_ENCODING = {"Vectorial": "VectorialWave", "Wavelet": "WaveletWave", "Quantized": "WaveletWave"}


@dataclass
class VersionReport:
    """What :func:`normalise` recognised and changed.

    Attributes:
        recognised: label of the reference release whose reader reads this shape.
        version_field: the document's ``version`` string as written (``None`` when absent).
        changes: one ``{"path", "change"}`` per normalisation, by JSON path.
        legacy_wavelet_samples: paths of wavelet effects that carry pre-2024 coefficient keyframes.
    """

    recognised: str
    version_field: str | None
    changes: list[dict[str, str]] = field(default_factory=list)
    legacy_wavelet_samples: list[str] = field(default_factory=list)

    def add(self, path: str, change: str) -> None:
        """Record one change at JSON path ``path``."""
        self.changes.append({"path": path or "$", "change": change})

    def to_dict(self) -> dict[str, Any]:
        """JSON form (``import --json`` prints it as ``format_version``)."""
        return {"recognised": self.recognised, "version_field": self.version_field,
                "normalised": list(self.changes), "changes": len(self.changes)}


def _rename(obj: dict[str, Any], old: str, new: str, path: str, rep: VersionReport) -> None:
    if old in obj:
        if new in obj:
            raise FormatError(f"both {old!r} (older name) and {new!r} are present", field=f"{path}.{old}")
        # keep the key order readable: rebuild with the new name in place
        items = [(new if k == old else k, v) for k, v in obj.items()]
        obj.clear()
        obj.update(items)
        rep.add(f"{path}.{old}", f"renamed {old} -> {new}")


def _recognise(doc: dict[str, Any]) -> str:
    percs = doc.get("perceptions")
    percs = percs if isinstance(percs, list) else []
    has = {"tracks": False, "encoding": False, "weight": False, "coefficient": False, "zero_block": False}
    for p in percs:
        if not isinstance(p, dict):
            continue
        chans = p.get("tracks") if "tracks" in p else p.get("channels")
        has["tracks"] |= "tracks" in p
        for c in chans if isinstance(chans, list) else []:
            if not isinstance(c, dict):
                continue
            has["weight"] |= "mixing_weight" in c
            has["coefficient"] |= "mixing_coefficient" in c
            bands = c.get("bands")
            for b in bands if isinstance(bands, list) else []:
                if isinstance(b, dict):
                    has["encoding"] |= "encoding_modality" in b or b.get("band_type") == "Wave"
                    has["zero_block"] |= "block_length" in b and b.get("band_type") != "WaveletWave"
    if has["tracks"]:
        return RELEASES[0][0] if has["encoding"] else RELEASES[1][0]
    if has["weight"] or (has["zero_block"] and not has["coefficient"]):
        return RELEASES[2][0]
    return CURRENT


def normalise(doc: Any) -> tuple[Any, VersionReport]:
    """Rewrite a decoded ``.hjif`` document of any published shape into the current one
    (in place) and report what changed. Non-object parts are left for the parser to name."""
    if not isinstance(doc, dict):
        return doc, VersionReport(CURRENT, None)
    version = doc.get("version")
    rep = VersionReport(_recognise(doc), version if isinstance(version, str) else None)
    if rep.recognised != CURRENT:
        for key, default in (("profile", "Main"), ("level", 1), ("syncs", [])):
            if key not in doc:
                doc[key] = default
                rep.add(key, f"absent before CRM3.1: {key} = {default!r}")
    percs = doc.get("perceptions")
    for i, p in enumerate(percs if isinstance(percs, list) else []):
        if isinstance(p, dict):
            _perception(p, f"perceptions[{i}]", rep)
    return doc, rep


def _perception(p: dict[str, Any], path: str, rep: VersionReport) -> None:
    _rename(p, "tracks", "channels", path, rep)
    if "effect_library" not in p and "channels" in p and rep.recognised == RELEASES[0][0]:
        p["effect_library"] = []
        rep.add(f"{path}.effect_library", "absent before CRM2: empty effect library")
    lib = p.get("effect_library")
    for j, e in enumerate(lib if isinstance(lib, list) else []):
        if isinstance(e, dict):
            _effect(e, f"{path}.effect_library[{j}]", "VectorialWave", rep)
    chans = p.get("channels")
    for j, c in enumerate(chans if isinstance(chans, list) else []):
        if not isinstance(c, dict):
            continue
        cpath = f"{path}.channels[{j}]"
        _rename(c, "mixing_weight", "mixing_coefficient", cpath, rep)
        bands = c.get("bands")
        for k, b in enumerate(bands if isinstance(bands, list) else []):
            if isinstance(b, dict):
                _band(b, f"{cpath}.bands[{k}]", rep)


def _band(b: dict[str, Any], path: str, rep: VersionReport) -> None:
    enc = b.pop("encoding_modality", None)
    if b.get("band_type") == "Wave":
        new = _BAND_FROM_ENCODING.get(enc if isinstance(enc, str) else "")
        if new is None:
            raise FormatError(f"band_type 'Wave' (CRM0/CRM1) needs encoding_modality Vectorial, Wavelet or "
                              f"Quantized, got {enc!r}", field=f"{path}.band_type")
        b["band_type"] = new
        rep.add(f"{path}.band_type", f"'Wave' with encoding_modality {enc!r} (CRM0/CRM1) -> {new!r}")
    elif enc is not None:
        rep.add(f"{path}.encoding_modality", "dropped (CRM0/CRM1 field; the band type says it)")
    _rename(b, "window_length", "block_length", path, rep)
    btype = b.get("band_type")
    if "block_length" in b:
        bl = b["block_length"]
        if btype != "WaveletWave":
            del b["block_length"]
            rep.add(f"{path}.block_length", f"dropped {bl!r} on a {btype} band (CRM3-CRM3.2 write it on every band)")
        elif isinstance(bl, float) and bl.is_integer():
            b["block_length"] = int(bl)
            rep.add(f"{path}.block_length", f"{bl!r} -> {int(bl)} (a real number before CRM4)")
    effs = b.get("effects")
    for i, e in enumerate(effs if isinstance(effs, list) else []):
        if isinstance(e, dict):
            _effect(e, f"{path}.effects[{i}]", btype, rep)


def _effect(e: dict[str, Any], path: str, band_type: Any, rep: VersionReport) -> None:
    if "effect_type" not in e and rep.recognised == RELEASES[0][0]:
        e["effect_type"] = "Basis"
        rep.add(f"{path}.effect_type", "absent before CRM2: 'Basis'")
    if e.get("effect_type") == "Timeline":
        e["effect_type"] = "Composite"
        rep.add(f"{path}.effect_type", "'Timeline' (CRM2-CRM3.2) -> 'Composite'")
    _rename(e, "semantic", "semantic_keywords", path, rep)
    kfs = e.get("keyframes")
    if not isinstance(kfs, list) or not kfs or not all(isinstance(k, dict) for k in kfs):
        return
    if band_type == "WaveletWave":
        if "wavelet_stream" not in e and e.get("effect_type", "Basis") == "Basis":
            rep.legacy_wavelet_samples.append(path)
            rep.add(f"{path}.keyframes", f"{len(kfs)} wavelet coefficients as keyframes (before CRM4): not decoded, not played")
            del e["keyframes"]
            e["wavelet_stream"] = ""
        return
    if not all(_valid_keyframe(k) for k in kfs):
        return  # the parser names the bad value at its path as written
    positions = [k.get("relative_position") for k in kfs]
    seq = [0 if p is None else p for p in positions]
    first_bad = next((i for i in range(1, len(seq)) if seq[i] < max(seq[:i])), None)
    if first_bad is None:
        return
    before = max(seq[:first_bad])
    why = (f"relative_position {seq[first_bad]} after {before}"
           + (" (a 16-bit sentinel position)" if before >= SENTINEL_MIN else ""))
    if band_type in ("Transient", "Curve"):
        e["keyframes"] = [kfs[i] for i in sorted(range(len(kfs)), key=lambda i: seq[i])]
        rep.add(f"{path}.keyframes[{first_bad}]", f"keyframes out of order ({why}): sorted by position")
        return
    if len(kfs) > MAX_REORDER_KEYFRAMES:
        raise ContentBudgetError(f"{len(kfs)} keyframes out of order ({why}); at most {MAX_REORDER_KEYFRAMES} are "
                                 "rewritten as the reference reads them (docs/safety.md)", field=f"{path}.keyframes")
    e["keyframes"] = _reference_reading(kfs)
    rep.add(f"{path}.keyframes[{first_bad}]",
            f"keyframes out of order ({why}): rewritten as the reference reader reads them "
            f"(first keyframe at or after t in file order); {len(kfs)} -> {len(e['keyframes'])} keyframes")


def _valid_keyframe(k: dict[str, Any]) -> bool:
    """Whether every field of a keyframe is of a type and range the parser accepts (only
    such keyframes are reordered, so an error still names the path as written)."""
    p, a, f = k.get("relative_position"), k.get("amplitude_modulation"), k.get("frequency_modulation")
    ok_p = p is None or (isinstance(p, int) and not isinstance(p, bool) and 0 <= p <= 2 ** 31 - 1)
    ok_a = a is None or (_num(a) is not None and -1.0 <= a <= 1.0)
    ok_f = f is None or (_num(f) is not None and 0.0 <= f <= 65535.0)
    return ok_p and ok_a and ok_f


# ---------------------------------------------------------------- the reference's reading
_num = finite_float   # a finite JSON number as a float, else None


def _ref_line(t0: float, a0: float, t1: float, a1: float, x: float) -> float:
    """The reference's two-point interpolation: held outside [t0, t1], either order."""
    if x < t0:
        return a0
    if x > t1:
        return a1
    if t0 >= t1:
        t0, t1, a0, a1 = t1, t0, a1, a0
    if t1 == t0:
        return a1
    return (a0 * (t1 - x) + a1 * (x - t0)) / (t1 - t0)


def _reading(kfs: list[dict[str, Any]], key: str, x: float, default: float | None) -> float | None:
    """Value of ``key`` at ``x`` as the reference synthesiser reads a file-ordered list:
    the first keyframe with the value (and a position; for frequencies a keyframe without
    one counts as position 0) at or after ``x`` in file order,
    interpolated with the keyframe before it in file order; after the last, the last
    keyframe's value; ``default`` without any."""
    have: list[tuple[Any, Any]] = [(k.get("relative_position"), _num(k.get(key))) for k in kfs]
    if key == "frequency_modulation":  # the reference's frequency search takes no position as 0
        have = [(0 if p is None else p, v) for p, v in have]
    idx = [i for i, (_, v) in enumerate(have) if v is not None]
    if not idx:
        return default
    after = next((i for i in idx if have[i][0] is not None and have[i][0] >= x), None)
    if after is None:
        return have[idx[-1]][1]
    prev = [i for i in idx if i < after]
    if not prev:
        return have[after][1]
    b = prev[-1]
    t0 = 0.0 if have[b][0] is None else float(have[b][0])
    return _ref_line(t0, have[b][1], float(have[after][0]), have[after][1], x)  # type: ignore[arg-type]


def _reference_reading(kfs: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Sorted keyframes that give the amplitude and frequency the reference reads from the
    file-ordered ``kfs`` over the effect's span (0 .. last positioned keyframe in file order)."""
    positioned = [k["relative_position"] for k in kfs if k.get("relative_position") is not None]
    span = float(positioned[-1]) if positioned else 0.0
    xs = sorted({0.0, span, *(float(p) for p in positioned if 0 <= p <= span)})
    has_amp = any(_num(k.get("amplitude_modulation")) is not None for k in kfs)
    has_freq = any(_num(k.get("frequency_modulation")) is not None for k in kfs)

    def point(x: float) -> dict[str, Any]:
        d: dict[str, Any] = {"relative_position": int(x)}
        if has_amp:
            d["amplitude_modulation"] = _reading(kfs, "amplitude_modulation", x, 1.0)
        if has_freq:
            d["frequency_modulation"] = _reading(kfs, "frequency_modulation", x, None)
        return d

    out: list[dict[str, Any]] = []
    for j, x in enumerate(xs):
        left = point(x)
        out.append(left)
        if j + 1 < len(xs):
            # the reading is linear on (x, next x]; its value just right of x, extrapolated
            # back to x from two interior points, shows a step at x
            nx = xs[j + 1]
            a, b = x + (nx - x) / 3.0, x + 2.0 * (nx - x) / 3.0
            pa, pb = point(a), point(b)
            right = {"relative_position": int(x)}
            step = False
            for key in ("amplitude_modulation", "frequency_modulation"):
                if key in left and pa.get(key) is not None and pb.get(key) is not None:
                    v = 2.0 * pa[key] - pb[key]
                    if key == "amplitude_modulation":
                        v = min(1.0, max(-1.0, v))
                    right[key] = v
                    step |= abs(v - left[key]) > 1e-9 * max(1.0, abs(v))
                elif key in left:
                    right[key] = left[key]
            if step:
                out.append(right)
    return out

"""Object geometry in the device workspace: poses, shapes and the per-tick hit test.

Coordinates are the device workspace's, in mm, as in
:class:`~hapticsdk.devices.actuators.DeviceState`: x lateral (the sliding direction of the
scripted fingers), y up (the surface normal of a version-1 scene, whose material
surface is the plane y = 0 with its inside at y < 0), z towards the user.

A :class:`Pose` places a shape: ``world = R @ local + position``. Each shape answers
:meth:`Shape.contact` with ``(penetration_mm, nx, ny, nz)`` -- the depth of the probe
point inside the solid (> 0) and the outward unit normal (world frame) at the closest
surface point -- or None when the point is not inside. :meth:`Shape.probe` answers the
same for every point: outside, the penetration is minus the distance to the solid
(<= 0) and the normal points from the closest surface point towards the probe.

Shapes (local frames):

* :class:`PlanePatch`: the surface is the local plane y = 0 with outward normal local
  +y (``normal`` re-orients it). Finite patch: the rectangle ``|x| <= hx, |z| <= hz``
  over a *skin* of ``thickness_mm`` below it (default 10 mm): the solid is the slab
  ``[-hx, hx] x [-thickness, 0] x [-hz, hz]``, so a probe far below the patch (or
  beside it) is not in contact. A patch is one-sided: anywhere inside its slab the
  penetration is the depth below the surface and the normal is the surface normal,
  even when the probe came in through a side. With no ``half_size_mm`` it is an
  *infinite plane*, by default a half-space (no skin): the version-1 surface.
* :class:`Box`: half sizes ``(hx, hy, hz)``; inside, the penetration is the distance
  to the nearest face and the normal that face's normal. Where faces are equally near
  (edges, corners, the centre of a cube) the tie goes to y, then x, then z (pressing
  from above is the common case), and a coordinate of exactly 0 counts as positive.
* :class:`Sphere`: ``radius_mm``; normal radial (at the exact centre: world +y).

:class:`HitTester` finds, per servo tick, the object the probe touches, in plain
Python floats (no numpy on the per-tick path). Its rule when several objects contain
the probe -- *the object already in contact keeps the contact while it still contains
the probe; otherwise the deepest penetration wins, ties to the lower index* -- means
that sliding across a shared edge or an overlap switches objects exactly once, when
the probe leaves the old object, instead of flickering. Benchmark:
``python bench/bench_hittest.py`` (figures in ``docs/runtime.md``).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from bisect import bisect_left
from typing import Any, ClassVar, Mapping, Sequence

from ..errors import ValidationError

#: ``(penetration_mm, nx, ny, nz)``
Contact = tuple[float, float, float, float]
#: ``(object index or -1, penetration_mm, nx, ny, nz)``
Hit = tuple[int, float, float, float, float]
Matrix3 = tuple[tuple[float, float, float], tuple[float, float, float], tuple[float, float, float]]

#: a unit quaternion or normal read from a file may be off by this much (then normalised)
UNIT_TOLERANCE = 1e-3
#: a rotation matrix must be orthonormal to this tolerance
ORTHONORMAL_TOLERANCE = 1e-6
#: skin of a finite plane patch when none is given (mm)
DEFAULT_PATCH_THICKNESS_MM = 10.0

_IDENTITY: Matrix3 = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


# -- validation helpers -------------------------------------------------------
def _number(v: Any, field: str) -> float:
    # the shared check (hapticsdk.checks): also an int beyond the float range (JSON reads
    # a 1 followed by 400 zeros as one), which float() refuses with an OverflowError
    from ..checks import check_number
    return check_number(v, field)


def _positive(v: Any, field: str) -> float:
    f = _number(v, field)
    if f <= 0.0:
        raise ValidationError(f"must be > 0 mm, got {v!r}", field=field)
    return f


def _vector(v: Any, n: int, field: str) -> tuple[float, ...]:
    if isinstance(v, (str, bytes, Mapping)) or not hasattr(v, "__len__") or len(v) != n:
        raise ValidationError(f"expected {n} numbers, got {v!r}", field=field)
    return tuple(_number(c, f"{field}[{i}]") for i, c in enumerate(v))


def _unit(v: Any, n: int, field: str, what: str) -> tuple[float, ...]:
    c = _vector(v, n, field)
    norm = math.sqrt(sum(x * x for x in c))
    if abs(norm - 1.0) > UNIT_TOLERANCE:
        raise ValidationError(f"{what} must have unit length (within {UNIT_TOLERANCE}), got length "
                              f"{norm:.6g}", field=field)
    return tuple(x / norm for x in c)


# -- rotations ------------------------------------------------------------------
def quaternion_matrix(w: float, x: float, y: float, z: float) -> Matrix3:
    """Rotation matrix of the unit quaternion ``(w, x, y, z)`` (normalised first)."""
    n = math.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w / n, x / n, y / n, z / n
    return ((1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)),
            (2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)),
            (2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)))


def euler_matrix(rx_deg: float, ry_deg: float, rz_deg: float) -> Matrix3:
    """``Rz @ Ry @ Rx``: rotate about the world x axis by ``rx_deg``, then about world y,
    then about world z (degrees, right-handed)."""
    a, b, c = math.radians(rx_deg), math.radians(ry_deg), math.radians(rz_deg)
    ca, sa, cb, sb, cc, sc = math.cos(a), math.sin(a), math.cos(b), math.sin(b), math.cos(c), math.sin(c)
    return ((cc * cb, cc * sb * sa - sc * ca, cc * sb * ca + sc * sa),
            (sc * cb, sc * sb * sa + cc * ca, sc * sb * ca - cc * sa),
            (-sb, cb * sa, cb * ca))


def matrix_quaternion(m: Matrix3) -> tuple[float, float, float, float]:
    """Unit quaternion ``(w, x, y, z)`` (w >= 0) of a rotation matrix."""
    (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = m
    tr = m00 + m11 + m22
    if tr > 0:
        s = 2.0 * math.sqrt(tr + 1.0)
        q = (0.25 * s, (m21 - m12) / s, (m02 - m20) / s, (m10 - m01) / s)
    elif m00 > m11 and m00 > m22:
        s = 2.0 * math.sqrt(1.0 + m00 - m11 - m22)
        q = ((m21 - m12) / s, 0.25 * s, (m01 + m10) / s, (m02 + m20) / s)
    elif m11 > m22:
        s = 2.0 * math.sqrt(1.0 + m11 - m00 - m22)
        q = ((m02 - m20) / s, (m01 + m10) / s, 0.25 * s, (m12 + m21) / s)
    else:
        s = 2.0 * math.sqrt(1.0 + m22 - m00 - m11)
        q = ((m10 - m01) / s, (m02 + m20) / s, (m12 + m21) / s, 0.25 * s)
    if q[0] < 0:
        q = (-q[0], -q[1], -q[2], -q[3])
    n = math.sqrt(sum(c * c for c in q))
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


def _matmul(a: Matrix3, b: Matrix3) -> Matrix3:
    return tuple(tuple(sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3))  # type: ignore[return-value]
                 for i in range(3))


def _rotation_to(n: Sequence[float]) -> Matrix3:
    """The smallest rotation taking +y to the unit vector ``n``."""
    nx, ny, nz = n
    # axis = y x n = (nz, 0, -nx), sin(angle) = its length, cos(angle) = ny: Rodrigues.
    # Only a normal exactly along y has no axis; any other, however close to y, is
    # rotated to exactly (a threshold on ny snapped normals within 1.4e-6 rad of y to it)
    m = max(abs(nx), abs(nz))
    if m == 0.0:
        if ny > 0.0:
            return _IDENTITY
        return ((1.0, 0.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, -1.0))   # half turn about x
    # the axis scaled by its larger component before it is normalised: (nz, -nx) divided
    # by its subnormal length loses its direction (5e-324 / 7e-324 rounds to 1)
    ax, az = nz / m, -nx / m
    k = math.hypot(ax, az)
    ax, az = ax / k, az / k
    c, si = ny, m * k
    t = 1.0 - c
    return ((c + ax * ax * t, -az * si, ax * az * t),
            (az * si, c, -ax * si),
            (ax * az * t, ax * si, c + az * az * t))


class Pose:
    """Where a shape is: ``world = R @ local + position_mm``.

    Args:
        position_mm: ``(x, y, z)`` of the shape's local origin in the workspace (mm).
        rotation: None (identity); ``{"quaternion_wxyz": [w, x, y, z]}`` (unit length
            within :data:`UNIT_TOLERANCE`, then normalised); ``{"euler_deg": [rx, ry,
            rz]}`` (about the world x, then y, then z axis: ``R = Rz Ry Rx``, degrees);
            or a 3x3 rotation matrix (rows; orthonormal with determinant +1).
        field: name used in validation errors (``scene.objects[0].pose``).

    Attributes:
        position_mm: ``(x, y, z)`` floats (mm).
        matrix: the rotation ``R`` as a tuple of three row tuples.
    """

    __slots__ = ("position_mm", "matrix", "_spec")

    def __init__(self, position_mm: Sequence[float] = (0.0, 0.0, 0.0), rotation: Any = None, *,
                 field: str = "pose") -> None:
        self.position_mm: tuple[float, float, float] = _vector(position_mm, 3, f"{field}.position_mm")  # type: ignore[assignment]
        self._spec: dict[str, list[float]] | None = None
        rf = f"{field}.rotation"
        if rotation is None:
            self.matrix: Matrix3 = _IDENTITY
        elif isinstance(rotation, Mapping):
            keys = set(rotation)
            if keys == {"quaternion_wxyz"}:
                q = _unit(rotation["quaternion_wxyz"], 4, f"{rf}.quaternion_wxyz", "a rotation quaternion")
                self.matrix = quaternion_matrix(*q)
                self._spec = {"quaternion_wxyz": list(q)}
            elif keys == {"euler_deg"}:
                e = _vector(rotation["euler_deg"], 3, f"{rf}.euler_deg")
                self.matrix = euler_matrix(*e)
                self._spec = {"euler_deg": list(e)}
            else:
                raise ValidationError(f"expected exactly one of 'quaternion_wxyz' or 'euler_deg', got "
                                      f"{sorted(keys)}", field=rf)
        else:
            if isinstance(rotation, (str, bytes)) or not hasattr(rotation, "__len__") or len(rotation) != 3:
                raise ValidationError(f"expected a 3x3 rotation matrix or a mapping, got {rotation!r}", field=rf)
            m = tuple(_vector(row, 3, f"{rf}[{i}]") for i, row in enumerate(rotation))
            for i in range(3):
                for j in range(3):
                    dot = sum(m[i][k] * m[j][k] for k in range(3))
                    if abs(dot - (1.0 if i == j else 0.0)) > ORTHONORMAL_TOLERANCE:
                        raise ValidationError("rotation matrix is not orthonormal", field=rf)
            det = (m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
                   - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
                   + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]))
            if det < 0:
                raise ValidationError("rotation matrix is a reflection (determinant -1)", field=rf)
            self.matrix = m  # type: ignore[assignment]
            self._spec = {"quaternion_wxyz": list(matrix_quaternion(self.matrix))}

    @classmethod
    def from_dict(cls, data: Any, *, field: str = "pose") -> "Pose":
        """From the scene-file form ``{"position_mm": [x, y, z], "rotation": {...}}``."""
        if isinstance(data, Pose):
            return data
        if not isinstance(data, Mapping):
            raise ValidationError(f"expected an object, got {data!r}", field=field)
        extra = set(data) - {"position_mm", "rotation"}
        if extra:
            raise ValidationError(f"unknown keys {sorted(extra)}", field=field)
        return cls(data.get("position_mm", (0.0, 0.0, 0.0)), data.get("rotation"), field=field)

    def to_dict(self) -> dict[str, Any]:
        """The scene-file form (the rotation as given: quaternion or Euler degrees)."""
        d: dict[str, Any] = {"position_mm": list(self.position_mm)}
        if self._spec is not None:
            d["rotation"] = {k: list(v) for k, v in self._spec.items()}
        return d

    @property
    def is_identity_rotation(self) -> bool:
        """Whether the pose does not rotate (translation only)."""
        return self.matrix == _IDENTITY

    def apply(self, x: float, y: float, z: float) -> tuple[float, float, float]:
        """Local point -> world point (mm)."""
        (a, b, c), (d, e, f), (g, h, i) = self.matrix
        px, py, pz = self.position_mm
        return (a * x + b * y + c * z + px, d * x + e * y + f * z + py, g * x + h * y + i * z + pz)

    def rotate(self, x: float, y: float, z: float) -> tuple[float, float, float]:
        """Local direction -> world direction."""
        (a, b, c), (d, e, f), (g, h, i) = self.matrix
        return (a * x + b * y + c * z, d * x + e * y + f * z, g * x + h * y + i * z)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Pose) and self.position_mm == other.position_mm and self.matrix == other.matrix

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        return f"Pose(position_mm={self.position_mm!r}, rotation={self._spec!r})"


# -- shapes ---------------------------------------------------------------------
def _slab_interval(a: float, d: float, lo: float, hi: float, s0: float, s1: float) -> tuple[float, float]:
    """Intersect the parameter interval [s0, s1] of the line ``a + s d`` with lo <= . <= hi."""
    if d == 0.0:
        return (s0, s1) if lo <= a <= hi else (1.0, 0.0)
    u, v = (lo - a) / d, (hi - a) / d
    if u > v:
        u, v = v, u
    return (max(s0, u), min(s1, v))


class Shape(ABC):
    """A solid placed by a :class:`Pose` (mm). Immutable: :meth:`with_pose` returns a copy."""

    #: the ``geometry.shape`` name in scene files
    kind: ClassVar[str] = ""

    def __init__(self, pose: Pose | None = None) -> None:
        if pose is not None and not isinstance(pose, Pose):
            raise ValidationError("pose must be a hapticsdk.scene.geometry.Pose", field="pose")
        self.pose = pose or Pose()
        self._set_frame(self.pose.matrix)

    def _set_frame(self, m: Matrix3) -> None:
        """Cache the local frame (``world = m @ local + p``) as plain floats."""
        self._m = m
        (self._r00, self._r01, self._r02), (self._r10, self._r11, self._r12), (self._r20, self._r21, self._r22) = m
        self._px, self._py, self._pz = self.pose.position_mm

    # -- per-tick queries ---------------------------------------------------
    def probe(self, x: float, y: float, z: float) -> Contact:
        """``(penetration_mm, nx, ny, nz)`` for any point: penetration > 0 inside, else
        minus the distance to the solid; outward unit normal in world coordinates."""
        dx, dy, dz = x - self._px, y - self._py, z - self._pz
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = (self._r00, self._r01, self._r02, self._r10, self._r11,
                                                       self._r12, self._r20, self._r21, self._r22)
        pen, a, b, c = self._local(r00 * dx + r10 * dy + r20 * dz, r01 * dx + r11 * dy + r21 * dz,
                                   r02 * dx + r12 * dy + r22 * dz)
        return (pen, r00 * a + r01 * b + r02 * c, r10 * a + r11 * b + r12 * c, r20 * a + r21 * b + r22 * c)

    def contact(self, x: float, y: float, z: float) -> Contact | None:
        """``(penetration_mm > 0, nx, ny, nz)`` when ``(x, y, z)`` (mm) is inside, else None."""
        r = self.probe(x, y, z)
        return r if r[0] > 0.0 else None

    @abstractmethod
    def _local(self, x: float, y: float, z: float) -> Contact:
        """:meth:`probe` in the local frame."""

    # -- geometry -------------------------------------------------------------
    @property
    @abstractmethod
    def bound_radius_mm(self) -> float:
        """Radius of a sphere about ``pose.position_mm`` holding the solid (inf: unbounded)."""

    def _bounds(self) -> tuple[tuple[float, float], tuple[float, float], tuple[float, float]]:
        """The solid's local (lo, hi) extent per axis (mm), read by the default
        :meth:`surface_y`; a shape that overrides :meth:`surface_y` need not give it."""
        raise NotImplementedError(f"{type(self).__name__} overrides neither surface_y nor _bounds")

    def surface_y(self, x_mm: float, z_mm: float) -> float | None:
        """Height (mm) where a probe coming straight down at ``(x_mm, z_mm)`` first meets
        the solid, or None if the vertical line misses it."""
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = (self._r00, self._r01, self._r02, self._r10, self._r11,
                                                       self._r12, self._r20, self._r21, self._r22)
        dx, dz = x_mm - self._px, z_mm - self._pz
        # local point of world (x, py + s, z): a + s d, d = R^T e_y
        a = (r00 * dx + r20 * dz, r01 * dx + r21 * dz, r02 * dx + r22 * dz)
        d = (r10, r11, r12)
        s0, s1 = -math.inf, math.inf
        for k, (lo, hi) in enumerate(self._bounds()):
            s0, s1 = _slab_interval(a[k], d[k], lo, hi, s0, s1)
            if s0 > s1:
                return None
        return self._py + s1 if math.isfinite(s1) else None

    @abstractmethod
    def geometry_dict(self) -> dict[str, Any]:
        """The scene-file ``geometry`` form (without the pose)."""

    @abstractmethod
    def with_pose(self, pose: Pose) -> "Shape":
        """The same shape at another pose."""

    def __eq__(self, other: object) -> bool:
        return (type(other) is type(self) and self.geometry_dict() == other.geometry_dict()  # type: ignore[attr-defined]
                and self.pose == other.pose)  # type: ignore[attr-defined]

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.geometry_dict()!r}, pose={self.pose!r})"


class PlanePatch(Shape):
    """A plane surface: a finite rectangle over a skin, or an infinite plane.

    Args:
        half_size_mm: ``(hx, hz)`` half extents of the rectangle in its local x and z
            (mm); None: an infinite plane.
        thickness_mm: depth of the skin below the surface that still counts as inside
            (mm); default :data:`DEFAULT_PATCH_THICKNESS_MM` for a finite patch and
            unbounded (a half-space) for an infinite plane.
        normal: the outward normal in the local frame (unit; default ``(0, 1, 0)``);
            the world normal is ``pose.matrix @ normal``.
        pose: where the patch's centre is.
    """

    kind: ClassVar[str] = "plane"

    def __init__(self, half_size_mm: Sequence[float] | None = None, *, thickness_mm: float | None = None,
                 normal: Sequence[float] = (0.0, 1.0, 0.0), pose: Pose | None = None,
                 field: str = "geometry") -> None:
        if half_size_mm is None:
            self.half_size_mm: tuple[float, float] | None = None
            hx = hz = math.inf
        else:
            hx, hz = _vector(half_size_mm, 2, f"{field}.half_size_mm")
            for i, h in enumerate((hx, hz)):
                if h <= 0:
                    raise ValidationError(f"must be > 0 mm, got {h!r}", field=f"{field}.half_size_mm[{i}]")
            self.half_size_mm = (hx, hz)
        if thickness_mm is None:
            t = math.inf if half_size_mm is None else DEFAULT_PATCH_THICKNESS_MM
            self.thickness_mm: float | None = None
        else:
            t = _positive(thickness_mm, f"{field}.thickness_mm")
            self.thickness_mm = t
        self.normal: tuple[float, float, float] = _unit(normal, 3, f"{field}.normal", "the normal")  # type: ignore[assignment]
        self._hx, self._hz, self._t = hx, hz, t
        self._halfspace = half_size_mm is None and math.isinf(t)
        self._field = field
        super().__init__(pose)

    def _set_frame(self, m: Matrix3) -> None:
        super()._set_frame(m if self.normal == (0.0, 1.0, 0.0) else _matmul(m, _rotation_to(self.normal)))

    @property
    def infinite(self) -> bool:
        """Whether the plane has no edges (no half size given)."""
        return self.half_size_mm is None

    @property
    def world_normal(self) -> tuple[float, float, float]:
        """The outward unit normal in world coordinates."""
        return (self._r01, self._r11, self._r21)

    @property
    def bound_radius_mm(self) -> float:
        return math.sqrt(self._hx * self._hx + self._hz * self._hz + self._t * self._t)

    def _bounds(self) -> tuple[tuple[float, float], tuple[float, float], tuple[float, float]]:
        return ((-self._hx, self._hx), (-self._t, 0.0), (-self._hz, self._hz))

    def _local(self, x: float, y: float, z: float) -> Contact:
        if self._halfspace:
            return (-y, 0.0, 1.0, 0.0)
        hx, hz, t = self._hx, self._hz, self._t
        if -t < y < 0.0 and -hx <= x <= hx and -hz <= z <= hz:
            return (-y, 0.0, 1.0, 0.0)
        ex = x - hx if x > hx else (x + hx if x < -hx else 0.0)
        ey = y if y > 0.0 else (y + t if y < -t else 0.0)
        ez = z - hz if z > hz else (z + hz if z < -hz else 0.0)
        d = math.sqrt(ex * ex + ey * ey + ez * ez)
        if d == 0.0:
            return (0.0, 0.0, 1.0, 0.0)
        return (-d, ex / d, ey / d, ez / d)

    def geometry_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"shape": "plane"}
        if self.half_size_mm is not None:
            d["half_size_mm"] = list(self.half_size_mm)
        if self.thickness_mm is not None:
            d["thickness_mm"] = self.thickness_mm
        if self.normal != (0.0, 1.0, 0.0):
            d["normal"] = list(self.normal)
        return d

    def with_pose(self, pose: Pose) -> "PlanePatch":
        return PlanePatch(self.half_size_mm, thickness_mm=self.thickness_mm, normal=self.normal, pose=pose,
                          field=self._field)


class Box(Shape):
    """A box of half sizes ``(hx, hy, hz)`` (mm) about its pose's position."""

    kind: ClassVar[str] = "box"

    def __init__(self, half_size_mm: Sequence[float], *, pose: Pose | None = None, field: str = "geometry") -> None:
        h = _vector(half_size_mm, 3, f"{field}.half_size_mm")
        for i, v in enumerate(h):
            if v <= 0:
                raise ValidationError(f"must be > 0 mm, got {v!r}", field=f"{field}.half_size_mm[{i}]")
        self.half_size_mm: tuple[float, float, float] = h  # type: ignore[assignment]
        self._hx, self._hy, self._hz = h
        self._field = field
        super().__init__(pose)

    @property
    def bound_radius_mm(self) -> float:
        return math.sqrt(self._hx * self._hx + self._hy * self._hy + self._hz * self._hz)

    def _bounds(self) -> tuple[tuple[float, float], tuple[float, float], tuple[float, float]]:
        return ((-self._hx, self._hx), (-self._hy, self._hy), (-self._hz, self._hz))

    def _local(self, x: float, y: float, z: float) -> Contact:
        hx, hy, hz = self._hx, self._hy, self._hz
        qx, qy, qz = abs(x) - hx, abs(y) - hy, abs(z) - hz
        if qx < 0.0 and qy < 0.0 and qz < 0.0:
            # inside: the nearest face; ties to y, then x, then z
            if qy >= qx and qy >= qz:
                return (-qy, 0.0, 1.0 if y >= 0.0 else -1.0, 0.0)
            if qx >= qz:
                return (-qx, 1.0 if x >= 0.0 else -1.0, 0.0, 0.0)
            return (-qz, 0.0, 0.0, 1.0 if z >= 0.0 else -1.0)
        ex = qx if qx > 0.0 else 0.0
        ey = qy if qy > 0.0 else 0.0
        ez = qz if qz > 0.0 else 0.0
        d = math.sqrt(ex * ex + ey * ey + ez * ez)
        if d == 0.0:  # on a face: that face's normal (same tie order)
            if qy == 0.0:
                return (0.0, 0.0, 1.0 if y >= 0.0 else -1.0, 0.0)
            if qx == 0.0:
                return (0.0, 1.0 if x >= 0.0 else -1.0, 0.0, 0.0)
            return (0.0, 0.0, 0.0, 1.0 if z >= 0.0 else -1.0)
        return (-d, math.copysign(ex / d, x), math.copysign(ey / d, y), math.copysign(ez / d, z))

    def geometry_dict(self) -> dict[str, Any]:
        return {"shape": "box", "half_size_mm": list(self.half_size_mm)}

    def with_pose(self, pose: Pose) -> "Box":
        return Box(self.half_size_mm, pose=pose, field=self._field)


class Sphere(Shape):
    """A sphere of ``radius_mm`` (mm) about its pose's position (rotation has no effect)."""

    kind: ClassVar[str] = "sphere"

    def __init__(self, radius_mm: float, *, pose: Pose | None = None, field: str = "geometry") -> None:
        self.radius_mm = _positive(radius_mm, f"{field}.radius_mm")
        self._field = field
        super().__init__(pose)

    @property
    def bound_radius_mm(self) -> float:
        return self.radius_mm

    def probe(self, x: float, y: float, z: float) -> Contact:
        dx, dy, dz = x - self._px, y - self._py, z - self._pz
        d = math.sqrt(dx * dx + dy * dy + dz * dz)
        if d == 0.0:
            return (self.radius_mm, 0.0, 1.0, 0.0)
        return (self.radius_mm - d, dx / d, dy / d, dz / d)

    def _local(self, x: float, y: float, z: float) -> Contact:  # pragma: no cover - probe is overridden
        raise AssertionError("unused")

    def surface_y(self, x_mm: float, z_mm: float) -> float | None:
        dx, dz = x_mm - self._px, z_mm - self._pz
        h2 = self.radius_mm * self.radius_mm - dx * dx - dz * dz
        return self._py + math.sqrt(h2) if h2 >= 0.0 else None

    def geometry_dict(self) -> dict[str, Any]:
        return {"shape": "sphere", "radius_mm": self.radius_mm}

    def with_pose(self, pose: Pose) -> "Sphere":
        return Sphere(self.radius_mm, pose=pose, field=self._field)


SHAPES: dict[str, type[Shape]] = {"plane": PlanePatch, "box": Box, "sphere": Sphere}

_KEYS = {"plane": {"shape", "half_size_mm", "thickness_mm", "normal"}, "box": {"shape", "half_size_mm"},
         "sphere": {"shape", "radius_mm"}}


def shape_from_dict(geometry: Any, pose: Any = None, *, field: str = "geometry") -> Shape:
    """Build a shape from the scene-file form, e.g. ``{"shape": "sphere", "radius_mm": 20}``
    and ``{"position_mm": [0, 0, 0], "rotation": {...}}``. Errors name the field
    (``field + ".radius_mm"``)."""
    if not isinstance(geometry, Mapping):
        raise ValidationError(f"expected an object with a 'shape', got {geometry!r}", field=field)
    kind = geometry.get("shape")
    if not isinstance(kind, str) or kind not in SHAPES:
        raise ValidationError(f"unknown shape {kind!r}; valid: {sorted(SHAPES)}", field=f"{field}.shape")
    extra = set(geometry) - _KEYS[kind]
    if extra:
        raise ValidationError(f"unknown keys for a {kind}: {sorted(extra)}", field=field)
    pf = field.rsplit(".", 1)[0] + ".pose" if field.endswith(".geometry") else "pose"
    p = pose if isinstance(pose, Pose) else (Pose() if pose is None else Pose.from_dict(pose, field=pf))
    if kind == "sphere":
        if "radius_mm" not in geometry:
            raise ValidationError("a sphere needs radius_mm", field=f"{field}.radius_mm")
        return Sphere(geometry["radius_mm"], pose=p, field=field)
    if kind == "box":
        if "half_size_mm" not in geometry:
            raise ValidationError("a box needs half_size_mm [hx, hy, hz]", field=f"{field}.half_size_mm")
        return Box(geometry["half_size_mm"], pose=p, field=field)
    return PlanePatch(geometry.get("half_size_mm"), thickness_mm=geometry.get("thickness_mm"),
                      normal=geometry.get("normal", (0.0, 1.0, 0.0)), pose=p, field=field)


# -- hit test ---------------------------------------------------------------------
class HitTester:
    """Which object the probe touches, once per servo tick (plain floats, no numpy).

    Args:
        objects: ``(name, shape)`` pairs; the index of a pair is the object index
            :meth:`query` reports.

    :meth:`query` returns ``(index, penetration_mm, nx, ny, nz)``. In contact
    (``index >= 0``): the penetration (> 0) and outward unit normal of that object.
    Out of contact (``index == -1``): minus the distance (mm) to the nearest object and
    the normal at its closest point (``-inf`` and ``(0, 1, 0)`` with no objects).

    Overlap rule (hysteresis): the object in contact on the previous query keeps the
    contact as long as it still contains the probe, however deep another one is;
    otherwise the object with the deepest penetration wins, ties to the lower index.
    The tester is therefore stateful: use one per probe; :meth:`reset` forgets the held
    contact.

    Cost: the object held in contact is tested first (one exact test while the probe
    stays in it). Otherwise bounded objects are visited nearest-first along the
    horizontal axis (x or z) with the larger spread of their centres (a sorted list,
    rebuilt by :meth:`add`, :meth:`remove` and :meth:`set_pose`, searched by bisection);
    the search stops once the remaining ones are too far along that axis to contain the
    probe or to be nearer than the nearest surface found; each visited object gets a
    bounding-sphere check before its exact test. Unbounded objects (infinite planes)
    are always tested.
    """

    __slots__ = ("_names", "_shapes", "_current", "_probes", "_unbounded", "_keys", "_sorted", "_axis",
                 "_rbmax")

    def __init__(self, objects: Sequence[tuple[str, Shape]] = ()) -> None:
        self._names: list[str] = []
        self._shapes: list[Shape] = []
        self._current = -1
        for name, shape in objects:
            self._check(name, shape)
            self._names.append(name)
            self._shapes.append(shape)
        self._rebuild()

    @classmethod
    def single_plane(cls, name: str = "plane") -> "HitTester":
        """The version-1 surface: the infinite plane y = 0, normal +y; ``query`` returns
        penetration ``-y`` exactly (index 0 when ``-y > 0``)."""
        return cls([(name, PlanePatch())])

    # -- objects -----------------------------------------------------------
    @property
    def names(self) -> tuple[str, ...]:
        """Object names, in shape order."""
        return tuple(self._names)

    @property
    def shapes(self) -> tuple[Shape, ...]:
        """The objects' shapes, in object order."""
        return tuple(self._shapes)

    @property
    def current(self) -> int:
        """Index of the object held in contact (-1: none)."""
        return self._current

    def __len__(self) -> int:
        return len(self._shapes)

    def index(self, name: str) -> int:
        """Index of the object called ``name``."""
        try:
            return self._names.index(name)
        except ValueError:
            raise ValidationError(f"no object {name!r}; objects: {self._names}", field="name") from None

    def _check(self, name: str, shape: Shape) -> None:
        if not isinstance(name, str) or not name:
            raise ValidationError(f"object name must be a non-empty string, got {name!r}", field="name")
        if name in self._names:
            raise ValidationError(f"duplicate object name {name!r}", field="name")
        if not isinstance(shape, Shape):
            raise ValidationError(f"expected a Shape, got {shape!r}", field=f"objects.{name}")

    def _rebuild(self) -> None:
        """The per-tick tables (plain lists of floats)."""
        self._probes = [s.probe for s in self._shapes]
        self._unbounded = [(i, s.probe) for i, s in enumerate(self._shapes) if not math.isfinite(s.bound_radius_mm)]
        bounded = [(i, s) for i, s in enumerate(self._shapes) if math.isfinite(s.bound_radius_mm)]
        axis = 0
        if bounded:
            xs = [s.pose.position_mm[0] for _, s in bounded]
            zs = [s.pose.position_mm[2] for _, s in bounded]
            axis = 0 if max(xs) - min(xs) >= max(zs) - min(zs) else 2
        rows = sorted((s.pose.position_mm[axis], i, s.probe, *s.pose.position_mm, s.bound_radius_mm)
                      for i, s in bounded)
        self._axis = axis
        self._keys = [r[0] for r in rows]
        self._sorted = [r[1:] for r in rows]
        self._rbmax = max((r[6] for r in rows), default=0.0)

    def add(self, name: str, shape: Shape) -> int:
        """Append an object; returns its index."""
        self._check(name, shape)
        self._names.append(name)
        self._shapes.append(shape)
        self._rebuild()
        return len(self._shapes) - 1

    def remove(self, name: str) -> int:
        """Remove an object; later objects move down one index. Returns the removed index."""
        i = self.index(name)
        del self._names[i], self._shapes[i]
        if self._current == i:
            self._current = -1
        elif self._current > i:
            self._current -= 1
        self._rebuild()
        return i

    def set_pose(self, index: "int | str", pose: Pose) -> None:
        """Move object ``index`` (or the object of that name) to ``pose``."""
        i = self.index(index) if isinstance(index, str) else int(index)
        if not 0 <= i < len(self._shapes):
            raise ValidationError(f"no object {index!r}", field="index")
        if not isinstance(pose, Pose):
            raise ValidationError("expected a Pose", field="pose")
        self._shapes[i] = self._shapes[i].with_pose(pose)
        self._rebuild()

    def reset(self) -> None:
        """Forget the object held in contact."""
        self._current = -1

    # -- per tick ----------------------------------------------------------
    def query(self, x_mm: float, y_mm: float, z_mm: float) -> Hit:
        """``(index or -1, penetration_mm, nx, ny, nz)`` of the probe at ``(x, y, z)`` (mm)."""
        cur = self._current
        if cur >= 0:
            pen, nx, ny, nz = self._probes[cur](x_mm, y_mm, z_mm)
            if pen > 0.0:
                return (cur, pen, nx, ny, nz)
        best = -1
        best_pen = 0.0
        bx = bz = 0.0
        by = 1.0
        out = math.inf
        oi = -1
        ox = oz = 0.0
        oy = 1.0
        for i, probe in self._unbounded:
            pen, nx, ny, nz = probe(x_mm, y_mm, z_mm)
            if pen > 0.0:
                if pen > best_pen or (pen == best_pen and i < best):
                    best, best_pen, bx, by, bz = i, pen, nx, ny, nz
            elif -pen < out or (-pen == out and i < oi):
                out, oi, ox, oy, oz = -pen, i, nx, ny, nz
        keys = self._keys
        n = len(keys)
        if n:
            rows = self._sorted
            rbmax = self._rbmax
            c = x_mm if self._axis == 0 else z_mm
            hi = bisect_left(keys, c)
            lo = hi - 1
            while lo >= 0 or hi < n:
                # the next object nearest along the sort axis
                if hi < n and (lo < 0 or keys[hi] - c <= c - keys[lo]):
                    j = hi
                    d1 = keys[hi] - c
                    hi += 1
                else:
                    j = lo
                    d1 = c - keys[lo]
                    lo -= 1
                slack = 0.0 if best >= 0 else out
                if d1 > rbmax + slack:
                    break  # every remaining object is farther along the axis alone
                i, probe, cx, cy, cz, rb = rows[j]
                dx, dy, dz = x_mm - cx, y_mm - cy, z_mm - cz
                lim = rb + slack
                if dx * dx + dy * dy + dz * dz > lim * lim:
                    continue  # cannot hold the probe, cannot be nearer than the nearest so far
                pen, nx, ny, nz = probe(x_mm, y_mm, z_mm)
                if pen > 0.0:
                    if pen > best_pen or (pen == best_pen and i < best):
                        best, best_pen, bx, by, bz = i, pen, nx, ny, nz
                elif -pen < out or (-pen == out and i < oi):
                    out, oi, ox, oy, oz = -pen, i, nx, ny, nz
        self._current = best
        if best >= 0:
            return (best, best_pen, bx, by, bz)
        return (-1, -out, ox, oy, oz)

"""Spatial scenes: shapes, poses, the hit test, scene schema version 2, the finger walk."""

from __future__ import annotations

import copy
import json
import math
import random
from pathlib import Path

import numpy as np
import pytest

from hapticsdk.errors import ValidationError
from hapticsdk.scene import Scene, load_scene
from hapticsdk.scene.geometry import Box, HitTester, PlanePatch, Pose, Sphere, euler_matrix, quaternion_matrix
from hapticsdk.sim.finger import Trajectory, press_slide, walk, walk_over

SCENES = Path(__file__).resolve().parents[2] / "examples" / "scenes"
# float rounding of a few products and sums of numbers of order 100 mm
EPS = 1e-9


def close(a, b, tol=EPS):
    return all(abs(x - y) <= tol for x, y in zip(a, b, strict=True))


# -- shapes --------------------------------------------------------------------
def test_sphere_penetration_and_normals():
    s = Sphere(10.0, pose=Pose((1.0, 2.0, 3.0)))
    assert close(s.contact(1.0, 11.5, 3.0), (0.5, 0.0, 1.0, 0.0))       # north pole
    assert close(s.contact(1.0, -7.0, 3.0), (1.0, 0.0, -1.0, 0.0))      # south pole
    assert close(s.contact(-8.0, 2.0, 3.0), (1.0, -1.0, 0.0, 0.0))      # -x side
    assert close(s.contact(1.0, 2.0, 3.0), (10.0, 0.0, 1.0, 0.0))       # centre: +y by convention
    d = 4.0 / math.sqrt(3.0)
    assert close(s.contact(1.0 + d, 2.0 + d, 3.0 + d),
                 (6.0, 1 / math.sqrt(3), 1 / math.sqrt(3), 1 / math.sqrt(3)))
    assert s.contact(1.0, 12.0, 3.0) is None                              # on the surface
    assert s.contact(1.0, 20.0, 3.0) is None
    assert close(s.probe(1.0, 20.0, 3.0), (-8.0, 0.0, 1.0, 0.0))         # outside: minus the distance


def test_box_faces_edges_corners():
    b = Box((10.0, 5.0, 20.0), pose=Pose((100.0, 0.0, 0.0)))
    assert close(b.contact(100.0, 4.0, 0.0), (1.0, 0.0, 1.0, 0.0))       # top face
    assert close(b.contact(100.0, -4.5, 0.0), (0.5, 0.0, -1.0, 0.0))     # bottom face
    assert close(b.contact(109.0, 0.0, 0.0), (1.0, 1.0, 0.0, 0.0))       # +x face
    assert close(b.contact(91.5, 0.0, 0.0), (1.5, -1.0, 0.0, 0.0))       # -x face
    assert close(b.contact(100.0, 0.0, -19.0), (1.0, 0.0, 0.0, -1.0))    # -z face
    # edge between top and +x, equally near: the tie goes to y
    assert close(b.contact(109.0, 4.0, 0.0), (1.0, 0.0, 1.0, 0.0))
    # edge between +x and +z: x before z
    assert close(b.contact(109.0, 0.0, 19.0), (1.0, 1.0, 0.0, 0.0))
    # corner: y first
    assert close(b.contact(109.0, -4.0, -19.0), (1.0, 0.0, -1.0, 0.0))
    # nearer face wins over the tie order
    assert close(b.contact(109.5, 3.0, 0.0), (0.5, 1.0, 0.0, 0.0))
    assert b.contact(110.0, 0.0, 0.0) is None                             # on a face
    assert b.contact(111.0, 0.0, 0.0) is None
    # outside a corner: distance to the corner, normal along the diagonal
    pen, nx, ny, nz = b.probe(113.0, 9.0, 0.0)
    assert close((pen, nx, ny, nz), (-5.0, 0.6, 0.8, 0.0))
    pen, nx, ny, nz = b.probe(87.0, -9.0, 0.0)
    assert close((pen, nx, ny, nz), (-5.0, -0.6, -0.8, 0.0))


def test_plane_patch_skin_and_extent():
    p = PlanePatch((20.0, 10.0), thickness_mm=4.0, pose=Pose((0.0, 5.0, 0.0)))
    assert close(p.contact(19.0, 4.0, 9.0), (1.0, 0.0, 1.0, 0.0))
    assert close(p.contact(0.0, 1.5, 0.0), (3.5, 0.0, 1.0, 0.0))         # depth below the surface
    assert p.contact(0.0, 0.5, 0.0) is None                               # below the 4 mm skin
    assert p.contact(0.0, -100.0, 0.0) is None                            # far below: not in contact
    assert p.contact(21.0, 4.0, 0.0) is None                              # beside the rectangle
    assert p.contact(0.0, 4.0, -10.5) is None
    assert p.contact(0.0, 6.0, 0.0) is None                               # above
    assert close(p.probe(0.0, 8.0, 0.0), (-3.0, 0.0, 1.0, 0.0))
    assert close(p.probe(0.0, -1.0, 0.0), (-2.0, 0.0, -1.0, 0.0))        # under the skin
    # default skin of a finite patch is finite, an infinite plane is a half-space
    assert PlanePatch((5.0, 5.0)).contact(0.0, -1000.0, 0.0) is None
    inf = PlanePatch()
    assert close(inf.contact(1e4, -1000.0, -1e4), (1000.0, 0.0, 1.0, 0.0))
    skinned = PlanePatch(thickness_mm=3.0)
    assert skinned.contact(0.0, -2.0, 0.0) is not None and skinned.contact(0.0, -3.5, 0.0) is None


def test_rotated_poses():
    # box rotated 90 degrees about z: local x is world y, local y is world -x
    b = Box((10.0, 5.0, 20.0), pose=Pose((0.0, 0.0, 0.0), {"euler_deg": [0.0, 0.0, 90.0]}))
    assert close(b.contact(0.0, 9.0, 0.0), (1.0, 0.0, 1.0, 0.0), 1e-12)    # local +x face, world top
    assert close(b.contact(4.0, 0.0, 0.0), (1.0, 1.0, 0.0, 0.0), 1e-12)    # local -y face, world +x
    assert b.contact(7.0, 0.0, 0.0) is None                                # 7 > 5: outside after rotation
    assert b.contact(0.0, 8.0, 0.0) is not None                            # 8 < 10: inside after rotation
    # plane patch tilted 30 degrees about z: normal (-sin 30, cos 30, 0)
    p = PlanePatch((20.0, 20.0), pose=Pose((0.0, 0.0, 0.0), {"euler_deg": [0.0, 0.0, 30.0]}))
    n = (-0.5, math.sqrt(3) / 2, 0.0)
    assert close(p.world_normal, n, 1e-12)
    pen, *nn = p.contact(-0.5 * -1.0, math.sqrt(3) / 2 * -1.0, 0.0)        # 1 mm along -normal
    assert abs(pen - 1.0) < 1e-12 and close(nn, n, 1e-12)
    # the same tilt from a quaternion, and from a local normal
    q = Pose((0.0, 0.0, 0.0), {"quaternion_wxyz": [math.cos(math.radians(15)), 0.0, 0.0,
                                                    math.sin(math.radians(15))]})
    assert close(PlanePatch((20.0, 20.0), pose=q).world_normal, n, 1e-12)
    assert close(PlanePatch((20.0, 20.0), normal=n).world_normal, n, 1e-12)
    # sphere: rotation has no effect; a rotated, translated box at a known point
    r = Box((10.0, 10.0, 10.0), pose=Pose((50.0, 0.0, 0.0), {"euler_deg": [0.0, 0.0, 45.0]}))
    assert r.contact(50.0, 13.0, 0.0) is not None          # the corner points up: 10*sqrt(2) = 14.1 mm
    assert Box((10.0, 10.0, 10.0), pose=Pose((50.0, 0.0, 0.0))).contact(50.0, 13.0, 0.0) is None


def test_quaternion_euler_matrix_agree():
    rng = random.Random(1)
    for _ in range(20):
        a = [rng.uniform(-180, 180) for _ in range(3)]
        m = euler_matrix(*a)
        q = Pose((0, 0, 0), m)._spec["quaternion_wxyz"]
        assert np.allclose(quaternion_matrix(*q), m, atol=1e-12)
        assert np.allclose(np.asarray(m) @ np.asarray(m).T, np.eye(3), atol=1e-12)
    # euler order: Rz Ry Rx
    rx, rz = np.asarray(euler_matrix(30, 0, 0)), np.asarray(euler_matrix(0, 0, 40))
    assert np.allclose(euler_matrix(30, 0, 40), rz @ rx)


def test_surface_y():
    assert Sphere(10.0, pose=Pose((0.0, 50.0, 0.0))).surface_y(6.0, 8.0) == 50.0
    assert Sphere(10.0, pose=Pose((0.0, 50.0, 0.0))).surface_y(11.0, 0.0) is None
    assert Box((10.0, 5.0, 10.0), pose=Pose((0.0, 2.0, 0.0))).surface_y(9.0, -9.0) == 7.0
    tilted = PlanePatch((20.0, 20.0), pose=Pose((0.0, 0.0, 0.0), {"euler_deg": [0.0, 0.0, 45.0]}))
    assert abs(tilted.surface_y(5.0, 0.0) - 5.0) < 1e-9
    assert PlanePatch().surface_y(123.0, 4.0) == 0.0
    assert PlanePatch((5.0, 5.0)).surface_y(6.0, 0.0) is None


# -- the hit test -----------------------------------------------------------------
def test_single_plane_is_the_version_1_formula():
    ht = HitTester.single_plane()
    rng = random.Random(0)
    for _ in range(2000):
        x, y, z = rng.uniform(-300, 300), rng.uniform(-50, 50), rng.uniform(-300, 300)
        idx, pen, nx, ny, nz = ht.query(x, y, z)
        assert pen == -y                                   # exactly the old `pen = -p1`
        assert idx == (0 if -y > 0 else -1)
        assert (nx, ny, nz) == (0.0, 1.0, 0.0)


def test_overlap_rule_hysteresis_and_deepest():
    a = Box((10.0, 10.0, 10.0), pose=Pose((0.0, 0.0, 0.0)))
    b = Box((10.0, 12.0, 10.0), pose=Pose((15.0, 0.0, 0.0)))      # overlaps a for 5 <= x <= 10, taller
    ht = HitTester([("a", a), ("b", b)])
    assert ht.query(0.0, 9.0, 0.0)[0] == 0                      # enter a from above
    # slide into the overlap: b is deeper there (3 mm against 1 mm) but a holds the contact
    idx, pen, *_ = ht.query(8.0, 9.0, 0.0)
    assert idx == 0 and abs(pen - 1.0) < EPS
    idx, pen, *_ = ht.query(11.0, 9.0, 0.0)                     # left a: b takes over
    assert idx == 1 and abs(pen - 3.0) < EPS
    assert ht.query(8.0, 9.0, 0.0)[0] == 1                      # and holds it back across the overlap
    ht.reset()
    assert ht.query(8.0, 9.0, 0.0)[0] == 1                      # entered both at once: the deepest
    ht.query(0.0, 50.0, 0.0)                                     # leave everything
    assert ht.current == -1
    # a tie goes to the lower index
    twins = HitTester([("p", PlanePatch()), ("q", PlanePatch())])
    assert twins.query(0.0, -1.0, 0.0)[0] == 0


def test_hit_tester_matches_exhaustive_search():
    rng = random.Random(3)
    objs = []
    for i in range(30):
        pose = Pose((rng.uniform(-100, 100), rng.uniform(-20, 20), rng.uniform(-100, 100)),
                    {"euler_deg": [rng.uniform(-90, 90) for _ in range(3)]})
        kind = i % 3
        shape = (Box([rng.uniform(3, 20) for _ in range(3)], pose=pose) if kind == 0 else
                 Sphere(rng.uniform(3, 20), pose=pose) if kind == 1 else
                 PlanePatch((rng.uniform(3, 20), rng.uniform(3, 20)), thickness_mm=rng.uniform(1, 8), pose=pose))
        objs.append((f"o{i}", shape))
    ht = HitTester(objs)
    shapes = [s for _, s in objs]
    hits = 0
    for _ in range(3000):
        ht.reset()
        x, y, z = rng.uniform(-130, 130), rng.uniform(-40, 40), rng.uniform(-130, 130)
        idx, pen, nx, ny, nz = ht.query(x, y, z)
        res = [s.probe(x, y, z) for s in shapes]
        inside = [(r[0], -i) for i, r in enumerate(res) if r[0] > 0]
        if inside:
            hits += 1
            p, mi = max(inside)
            assert (idx, pen) == (-mi, p)
            assert (nx, ny, nz) == res[-mi][1:]
        else:
            assert idx == -1 and pen == max(r[0] for r in res)
        assert abs(nx * nx + ny * ny + nz * nz - 1.0) < 1e-9
    assert hits > 100   # the sample really exercises contacts


def test_hit_tester_add_remove_set_pose():
    ht = HitTester([("a", Sphere(5.0, pose=Pose((0.0, 0.0, 0.0)))), ("b", Sphere(5.0, pose=Pose((20.0, 0.0, 0.0))))])
    assert ht.names == ("a", "b")
    assert ht.query(20.0, 0.0, 0.0)[0] == 1
    ht.remove("a")                                  # b moves to index 0 and keeps its contact
    assert ht.names == ("b",) and ht.current == 0
    assert ht.query(20.0, 0.0, 0.0)[0] == 0
    ht.set_pose("b", Pose((-50.0, 0.0, 0.0)))
    assert ht.query(20.0, 0.0, 0.0)[0] == -1
    assert ht.query(-50.0, 1.0, 0.0)[0] == 0
    assert ht.add("c", Box((1.0, 1.0, 1.0))) == 1
    with pytest.raises(ValidationError):
        ht.add("c", Sphere(1.0))
    with pytest.raises(ValidationError):
        ht.remove("zz")
    assert HitTester().query(0.0, 0.0, 0.0) == (-1, -math.inf, 0.0, 1.0, 0.0)


# -- scene schema version 2 --------------------------------------------------------
V2 = {
    "schema_version": 2,
    "name": "desk",
    "objects": [
        {"name": "pad", "material": "S7", "geometry": {"shape": "box", "half_size_mm": [20, 5, 20]},
         "pose": {"position_mm": [0, 5, 0]}},
        {"name": "ball", "material": "S1", "geometry": {"shape": "sphere", "radius_mm": 15},
         "pose": {"position_mm": [60, 0, 0]}},
        {"name": "tile", "material": "S3", "geometry": {"shape": "plane", "half_size_mm": [20, 20], "thickness_mm": 5},
         "pose": {"position_mm": [120, 2, 0], "rotation": {"euler_deg": [0, 0, 10]}}},
    ],
}


def test_version_1_file_reads_as_the_plane_y0():
    scene = load_scene(SCENES / "library.json")
    ht = scene.hit_tester()
    assert ht.names == tuple(o.name for o in scene.objects)
    for o in scene.objects:
        assert isinstance(o.geometry, PlanePatch) and o.geometry.infinite and o.pose == Pose()
    assert ht.query(12.0, -1.5, 3.0) == (0, 1.5, 0.0, 1.0, 0.0)   # shared plane: the first object
    d = scene.to_dict()
    assert d["schema_version"] == 2
    assert d["objects"][0]["geometry"] == {"shape": "plane"}
    again = Scene.from_dict(json.loads(json.dumps(d)))
    assert again.to_dict() == d


def test_version_2_round_trip_and_hit_tester():
    scene = Scene.from_dict(copy.deepcopy(V2))
    assert isinstance(scene.objects[1].geometry, Sphere)
    assert scene.objects[2].pose.to_dict() == {"position_mm": [120.0, 2.0, 0.0],
                                                "rotation": {"euler_deg": [0.0, 0.0, 10.0]}}
    ht = scene.hit_tester()
    assert ht.query(0.0, 9.0, 0.0)[:2] == (0, pytest.approx(1.0))
    assert ht.query(60.0, 14.0, 0.0)[0] == 1
    assert ht.query(120.0, 1.0, 0.0)[0] == 2
    again = Scene.from_dict(json.loads(json.dumps(scene.to_dict())))
    assert again.to_dict() == scene.to_dict()
    assert again.objects == scene.objects                       # shapes and poses compare by value
    assert again.objects[2].geometry != PlanePatch((20.0, 20.0), thickness_mm=5.0)   # other pose


def _bad(path, value):
    d = copy.deepcopy(V2)
    o = d
    for k in path[:-1]:
        o = o[k]
    if value is KeyError:
        del o[path[-1]]
    else:
        o[path[-1]] = value
    return d


@pytest.mark.parametrize("path,value,field", [
    (("objects", 1, "geometry", "radius_mm"), -2, "scene.objects[1].geometry.radius_mm"),
    (("objects", 1, "geometry", "radius_mm"), 0, "scene.objects[1].geometry.radius_mm"),
    (("objects", 1, "geometry", "radius_mm"), float("nan"), "scene.objects[1].geometry.radius_mm"),
    (("objects", 1, "geometry", "radius_mm"), KeyError, "scene.objects[1].geometry.radius_mm"),
    (("objects", 0, "geometry", "half_size_mm"), [20, -5, 20], "scene.objects[0].geometry.half_size_mm[1]"),
    (("objects", 0, "geometry", "half_size_mm"), [20, 5], "scene.objects[0].geometry.half_size_mm"),
    (("objects", 2, "geometry", "normal"), [0, 2, 0], "scene.objects[2].geometry.normal"),
    (("objects", 2, "geometry", "thickness_mm"), float("inf"), "scene.objects[2].geometry.thickness_mm"),
    (("objects", 2, "pose", "rotation"), {"quaternion_wxyz": [1, 1, 0, 0]},
     "scene.objects[2].pose.rotation.quaternion_wxyz"),
    (("objects", 2, "pose", "position_mm"), [0, float("nan"), 0], "scene.objects[2].pose.position_mm[1]"),
    (("objects", 0, "geometry", "shape"), "cone", "scene.objects[0].geometry.shape"),
    (("schema_version",), 1, "scene.objects[0].geometry"),
    (("schema_version",), 3, "scene.schema_version"),
])
def test_geometry_validation_names_the_field(path, value, field):
    with pytest.raises(ValidationError) as ei:
        Scene.from_dict(_bad(path, value))
    assert ei.value.field == field


def test_scene_object_from_python_and_defaults():
    from hapticsdk.scene import SceneObject
    o = SceneObject("x", "S7", geometry={"shape": "sphere", "radius_mm": 3}, pose={"position_mm": [1, 2, 3]})
    assert isinstance(o.geometry, Sphere) and o.shape().pose.position_mm == (1.0, 2.0, 3.0)
    assert SceneObject("y", "S7", geometry=Box((1, 1, 1), pose=Pose((5, 0, 0)))).pose.position_mm == (5.0, 0.0, 0.0)
    with pytest.raises(ValidationError) as ei:
        SceneObject("z", "S7", geometry={"shape": "sphere", "radius_mm": -1})
    assert ei.value.field == "objects.z.geometry.radius_mm"
    assert isinstance(SceneObject("w", "S7").geometry, PlanePatch)


# -- the finger walk -------------------------------------------------------------------
def _visits(traj, ht, period_s=0.001):
    seq = []
    for k in range(int(traj.duration_s / period_s) + 1):
        x, y, z, *_ = traj.at3(k * period_s)
        i = ht.query(x, y, z)[0]
        if i >= 0 and (not seq or seq[-1] != i):
            seq.append(i)
    return seq


def test_walk_over_visits_every_object_in_order():
    scene = Scene.from_dict(copy.deepcopy(V2))
    traj = walk_over(scene, press_depth_mm=1.5, speed_mm_s=60.0)
    assert traj.has_z
    assert _visits(traj, scene.hit_tester()) == [0, 1, 2]
    # reversed order in the scene: the walk follows the scene's order
    rev = copy.deepcopy(V2)
    rev["objects"].reverse()
    s2 = Scene.from_dict(rev)
    assert _visits(walk_over(s2), s2.hit_tester()) == [0, 1, 2]
    # objects spread along z, some rotated
    shapes = [Box((8, 8, 8), pose=Pose((0, 0, -80), {"euler_deg": [0, 30, 0]})),
              Sphere(12, pose=Pose((10, -5, 0))),
              PlanePatch((15, 15), pose=Pose((-10, 3, 70), {"euler_deg": [10, 0, -15]}))]
    ht = HitTester([(f"o{i}", s) for i, s in enumerate(shapes)])
    assert _visits(walk_over(ht), ht) == [0, 1, 2]


def test_walk_presses_slides_and_lifts():
    traj = walk([[(0.0, 10.0, 0.0), (20.0, 10.0, 0.0)], [(50.0, 0.0, 5.0)]], press_depth_mm=2.0,
                speed_mm_s=40.0, approach_mm=3.0, hold_s=0.0, rest_s=0.0)
    y = traj.y
    assert y.max() == pytest.approx(13.0)           # clearance: highest surface + approach
    assert y.min() == pytest.approx(-2.0)           # second stroke: 2 mm into the surface at y = 0
    # the slide of the first stroke: 20 mm at 40 mm/s, 2 mm deep
    i = int(np.where((traj.x == 0.0) & (traj.y == 8.0))[0][0])
    assert traj.x[i + 1] == 20.0 and traj.y[i + 1] == 8.0
    assert traj.t[i + 1] - traj.t[i] == pytest.approx(0.5)
    assert traj.at3(traj.duration_s)[2] == 5.0
    # between the strokes the finger travels at the clearance height
    between = [traj.at3(k * 0.001)[1] for k in range(int(traj.duration_s / 0.001))
               if 20.0 < traj.at3(k * 0.001)[0] < 50.0]
    assert between and min(between) == pytest.approx(13.0)
    with pytest.raises(ValidationError):
        walk([], press_depth_mm=1.0)
    with pytest.raises(ValidationError):
        walk([[(0.0, 0.0, 0.0)]], press_depth_mm=-1.0)


def test_two_d_trajectories_unchanged():
    t = press_slide()
    assert not t.has_z and t.at3(0.7)[:2] == t.at(0.7)[:2] and t.at3(0.7)[2] == 0.0
    assert "z_mm" not in t.sample(0.01)
    assert not t.then(t).has_z
    three = Trajectory([(0, 0, 1, 5), (1, 10, 1, 15)])
    assert three.at3(0.5) == (5.0, 1.0, 10.0, 10.0, 0.0, 10.0)
    assert three.then(t).has_z


def test_probe_virtual_follows_the_walk_in_3d():
    from hapticsdk.sim.probe import VirtualProbe
    spread = copy.deepcopy(V2)
    for i, o in enumerate(spread["objects"]):
        o["pose"]["position_mm"][2] = 40.0 * (i - 1)          # objects at z = -40, 0, 40
    scene = Scene.from_dict(spread)
    traj = walk_over(scene)
    dev = VirtualProbe(trajectory=traj)
    dev.open()
    ht = scene.hit_tester()
    seq = []
    for _ in range(int(traj.duration_s / 0.001)):
        st = dev.read_state() if hasattr(dev, "read_state") else dev._read_state()
        x, y, z = (float(v) for v in st.position_mm)
        assert (x, y, z) == traj.at3(dev.t)[:3]
        i = ht.query(x, y, z)[0]
        if i >= 0 and (not seq or seq[-1] != i):
            seq.append(i)
        dev.step(0.001)
    assert seq == [0, 1, 2]


def test_omni_virtual_keeps_y_physical_and_x_z_kinematic():
    omni = pytest.importorskip("hapticsdk_hardness.omni")
    traj = walk([[(0.0, 0.0, -30.0), (20.0, 0.0, -30.0)], [(40.0, 0.0, 30.0)]], press_depth_mm=2.0)
    dev = omni.OmniVirtual(trajectory=traj)
    dev.open()
    lag = 0.0
    for _ in range(int(traj.duration_s / 0.001)):
        st = dev._read_state()
        x, y, z = (float(v) for v in st.position_mm)
        rx, ry, rz, *_ = traj.at3(dev.t)
        assert (x, z) == (rx, rz)                   # x and z: kinematic
        lag = max(lag, abs(y - ry))
        dev.step(0.001)
    assert lag > 0.01                               # y: through the arm dynamics, not a copy


def test_example_spatial_scene_file():
    scene = load_scene(SCENES / "desk-spatial.json")
    assert [type(o.geometry) for o in scene.objects] == [Box, Sphere, PlanePatch]
    assert _visits(walk_over(scene), scene.hit_tester()) == [0, 1, 2]

"""A scene file names no file to read: its ``settings.model`` is a model plugin's name.
A path there (``"x.onnx"``, anything with a slash) was handed to the ONNX reader by
compile_scene -- a file chosen by data; it is now refused by name, before any read.
Code may still pass a path."""

import pytest

from hapticsdk.devices.device_options import PrivilegedOptionError
from hapticsdk.scene import Scene


@pytest.mark.parametrize("model", ["/etc/passwd.onnx", "m.onnx", "M.ONNX", "../models/x", "sub\\x"])
def test_scene_file_naming_a_model_file_is_refused(tmp_path, model):
    p = tmp_path / "s.json"
    import json
    p.write_text(json.dumps({"objects": [{"material": "S7"}], "settings": {"model": model}}))
    for load in (lambda: Scene.load(p), lambda: Scene.from_dict(json.loads(p.read_text()))):
        with pytest.raises(PrivilegedOptionError) as exc:
            load()
        assert exc.value.field == "scene.settings.model"


def test_model_plugin_name_in_a_scene_file_and_a_path_from_code_are_kept():
    scene = Scene.from_dict({"objects": [{"material": "S7"}], "settings": {"model": "default"}})
    assert scene.settings["model"] == "default"
    assert Scene.for_material("S7", model="/opt/models/m.onnx").settings["model"] == "/opt/models/m.onnx"


@pytest.mark.parametrize("build", ["file", "code"])
def test_scene_cannot_choose_the_amortised_cache_folder(tmp_path, build):
    # the amortised solver read and wrote its tables in the folder the scene named
    from hapticsdk.compiler import compile_scene

    opts = {"cache_dir": str(tmp_path / "evil"), "grid": 5, "build_samples": 200, "build_iter": 2}
    settings = {"solver": {"method": "amortised", "options": opts}}
    scene = (Scene.from_dict({"objects": [{"material": "S7"}], "settings": settings}) if build == "file"
             else Scene.for_material("S7", **settings))
    with pytest.raises(PrivilegedOptionError) as exc:
        compile_scene(scene)
    assert exc.value.field == "scene.settings.solver.options.cache_dir"
    assert not (tmp_path / "evil").exists()


def test_code_still_passes_the_cache_folder_to_solve(tmp_path):
    import hapticsdk as hs

    res = hs.solve({"hardness": 0.5}, method="amortised",
                   options={"cache_dir": str(tmp_path), "grid": 5, "build_samples": 200, "build_iter": 2})
    assert res.error >= 0 and any((tmp_path / "amortised").iterdir())

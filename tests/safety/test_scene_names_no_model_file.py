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

"""hapticsdk-onnx's shipped model against the hapticsdk conformance kit."""

from __future__ import annotations

import pytest

from hapticsdk.testing import ModelConformance


class TestDefaultModel(ModelConformance):
    plugin_name = "default"


class TestOnnxFromPath(ModelConformance):
    """The same network loaded through the ``onnx`` class from its file path."""

    @pytest.fixture
    def model_factory(self):
        from hapticsdk_onnx import OnnxModel, default_model_path
        return lambda: OnnxModel(str(default_model_path()))

"""Perception-model training: recording format, generated data set, feature extraction,
Levenberg-Marquardt training of the 5-20-2 network, ONNX export.

Modules: :mod:`.recordings` (format, load/save, validation), :mod:`.generator`
(GENERATED data set), :mod:`.extraction` (GS, W, Fpeak, AFpeak, P), :mod:`.lm`
(training and metrics), :mod:`.onnx_export`, :mod:`.pipeline` (data-set files,
train-and-export, material library, data growth). See ``docs/perception-models.md``.
"""

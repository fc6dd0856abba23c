"""Perception: what a person feels, and the physical features that make them feel it.

The bottom stage every other one uses (it imports none of them):

* :mod:`~hapticsdk.perception.features`: ``Feature``, ``FeatureSpace``, the paper's G
  and the bounded spaces they span;
* :mod:`~hapticsdk.perception.dimensions`: ``PerceptionDimension`` (features,
  constraints, renderers), ``Constraint``, ``DimensionRenderer``, ``TickInput``,
  ``ChannelCommand``;
* :mod:`~hapticsdk.perception.models`: ``PerceptionModel``, the model I = f(G), batched;
* :mod:`~hapticsdk.perception.materials`: the named material library;
* :mod:`~hapticsdk.perception.channels`: ``CHANNELS``, the channel kinds a role asks for
  and an actuator serves.

The modules were ``hapticsdk.features``, ``hapticsdk.dimensions``, ``hapticsdk.models``,
``hapticsdk.materials`` and ``hapticsdk.channels`` until 0.2; those names still import, with a
``DeprecationWarning``, until 0.3. This package imports nothing on its own, so
``import hapticsdk`` stays light.
"""

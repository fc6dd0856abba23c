"""Budgets for hostile content in the readers of issue 31 (docs/safety.md, "Budgets"):
memory per input byte of the JSON reader, byte caps of the calibration and device
configuration readers. (Time per byte is linear and measured by hand, not asserted: a
timed unit test on a shared machine is a coin toss.)"""

from __future__ import annotations

import json
import os
import tracemalloc

import pytest

from hapticsdk.devices.device_options import ENV_CONFIG, MAX_CONFIG_BYTES, trusted_options
from hapticsdk.errors import ValidationError
from hapticsdk.schemas_io import MAX_JSON_BYTES, read_json

#: memory budget of read_json per input byte. The costliest JSON per byte is lists nested
#: in lists: each "[" + "]" is 2 input bytes for a list object (56 bytes) whose one-slot
#: item array is a separate allocation (16 bytes, the allocator's smallest) plus its slot in
#: the parent (8 bytes): 40 bytes per input byte (measured: 42 for "[[[[[[[[[[]]]]]]]]]]",
#: 22 for "[]" siblings, whose "," adds a byte each); the text is held twice (bytes, str),
#: 2 more; the bracket-depth scan before the parse (18 bytes per byte, freed before it)
#: is below that. 64 bytes per byte holds the worst of it with a half to spare.
BYTES_PER_BYTE = 64
N = 100_000

SHAPES = {
    "empty lists": "[" + ",".join(["[]"] * N) + "]",
    "empty objects": "[" + ",".join(["{}"] * N) + "]",
    "nested lists": "[" + ",".join(["[[[[[[[[[[]]]]]]]]]]"] * (N // 10)) + "]",
    "small ints": "[" + ",".join(["1"] * N) + "]",
    "keys": "{" + ",".join(f'"{i}":0' for i in range(N)) + "}",
    "strings": "[" + ",".join(['"a"'] * N) + "]",
}


def _peak_reading(p) -> int:
    """Peak traced memory (bytes) of ``read_json(p)``, after one read of a small file (the
    first read's one-off costs, about 6 MB of lazily built tables, are not per byte)."""
    warm = p.with_name("warm-up.json")
    warm.write_text('{"a": [1]}')
    read_json(warm, field="x")
    tracemalloc.start()
    try:
        read_json(p, field="x")
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


@pytest.mark.parametrize("shape", sorted(SHAPES))
def test_read_json_memory_per_input_byte(tmp_path, shape):
    p = tmp_path / "f.json"
    p.write_text(SHAPES[shape])
    size = p.stat().st_size
    peak = _peak_reading(p)
    assert peak <= BYTES_PER_BYTE * size, f"{shape}: {peak / size:.1f} bytes per input byte"


def test_a_small_file_does_not_reserve_the_cap(tmp_path):
    p = tmp_path / "small.json"
    p.write_text('{"a": 1}')
    assert _peak_reading(p) < MAX_JSON_BYTES // 1000  # the 64 MiB cap is not allocated for 8 bytes


def test_device_configuration_is_capped(tmp_path, monkeypatch):
    cfg = tmp_path / "devices.json"
    cfg.write_text(json.dumps({"piezo-virtual": {"note": "x" * MAX_CONFIG_BYTES}}))
    os.chmod(cfg, 0o600)
    monkeypatch.setenv(ENV_CONFIG, str(cfg))
    with pytest.raises(ValidationError, match="bytes"):
        trusted_options("piezo-virtual")
    cfg.write_text('{"piezo-virtual": {"gain": NaN}}')
    with pytest.raises(ValidationError) as ei:
        trusted_options("piezo-virtual")
    assert "piezo-virtual.gain" in ei.value.field

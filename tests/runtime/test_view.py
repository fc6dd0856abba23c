"""The live view (issue 27) in a real headless Chromium (Debian package chromium),
driven over the DevTools protocol on a pipe (``tests/view_page.py``): the page loads and
streams frames, a material switch shows on the page, and a screenshot kept as the test's
artefact (HAPTICSDK_TEST_ARTEFACTS, else the test's temporary directory). Skips naming
the package elsewhere; fails under CI=true. The page's frame rate and the switch's delay
are ``bench/bench_live_view.py``'s."""

import os
import shutil
from pathlib import Path

import pytest

from view_page import run_page


def _chromium():
    exe = shutil.which("chromium") or shutil.which("chromium-browser")
    if exe is None:
        if os.environ.get("CI") == "true":
            pytest.fail("chromium missing (Debian package chromium)")
        pytest.skip("chromium missing (Debian package chromium)")
    return exe


def test_view_in_headless_chromium(tmp_path):
    """What the page shows: frames that keep coming, the object in contact, the scene's
    materials, a material switch (shown after the servo rendered it: Date.now() has 1 ms
    steps, so -2 ms), a screenshot. How fast (the issue's goals: 30 frames a second or
    more, a switch shown within 100 ms) depends on how soon this machine runs the
    browser, the servo and the server: ``bench/bench_live_view.py`` measures it, not
    this test (printed here as a figure only)."""
    exe = _chromium()
    art = Path(os.environ.get("HAPTICSDK_TEST_ARTEFACTS") or tmp_path)
    art.mkdir(parents=True, exist_ok=True)
    p = run_page(exe, tmp_path / "profile", art / "live_view.png")
    assert p["url"].startswith("http://127.0.0.1:")
    assert p["frames"], "the page shows no frames"
    assert p["obj"] == "left"
    assert "S7" in p["objects"] and "simulated" in p["gen"]
    assert p["frames_advanced"], "the page's frames stopped"
    assert p["switch_rendered"] and p["switch_shown"], "the switch never showed"
    assert "0.9" in p["switch_text"] or "intensities" in p["switch_text"]
    print(f"view: {p['rate']:.1f} frames/s in the page; switch shown {p['delay_ms']:.1f} ms after the servo "
          f"rendered it; screenshot {art / 'live_view.png'}")
    assert p["png"][:8] == b"\x89PNG\r\n\x1a\n" and len(p["png"]) > 5000
    assert p["delay_ms"] >= -2.0   # shown after it was rendered (Date.now() has 1 ms steps)


def test_a_frame_with_non_finite_numbers_is_strict_json():
    """A NaN or infinity anywhere in a frame (a servo figure not measured yet) is sent as
    null: the browser's JSON.parse refuses NaN and would drop the whole frame."""
    import json

    import numpy as np

    from hapticsdk.runtime.view import _json

    def refuse(name):
        raise ValueError(f"not JSON: {name}")

    frame = {"t": float("nan"), "trace": [1.0, float("inf"), np.float64("-inf")],
             "timing": {"p99_us": np.float64("nan"), "ticks": 3}, "pair": (2.5, float("nan"))}
    back = json.loads(_json(frame), parse_constant=refuse)
    assert back == {"t": None, "trace": [1.0, None, None], "timing": {"p99_us": None, "ticks": 3},
                    "pair": [2.5, None]}


@pytest.mark.parametrize("port", [-1, 65536, 99999, 1.5, "80", True])
def test_a_port_that_is_not_a_tcp_port_is_named(port):
    """``open_view(port)`` / ``ViewServer``: a TCP port is a whole number 0..65535; 99999
    was an internal OverflowError from ``bind()`` (``hapticsdk view --port 99999``)."""
    from hapticsdk.errors import ValidationError
    from hapticsdk.runtime.view import ViewServer
    with pytest.raises(ValidationError, match="port"):
        ViewServer(None, port)


@pytest.mark.parametrize("argv, field", [(["--port", "99999"], "--port"), (["--speed", "0"], "--speed")])
def test_view_cli_names_a_bad_port_or_speed(argv, field, capsys):
    """``--speed 0`` was silently the default 40 mm/s; now refused like any other
    non-positive speed."""
    from hapticsdk.cli import main
    scene = Path(__file__).resolve().parents[2] / "examples" / "scenes" / "desk-spatial.json"
    assert main(["view", str(scene), "--seconds", "0.1", *argv]) == 2
    err = capsys.readouterr().err
    assert f"{field}:" in err and "internal error" not in err

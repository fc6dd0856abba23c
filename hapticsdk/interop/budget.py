"""Time and memory budgets for ``.hjif`` and ``.ahap`` content (see ``docs/safety.md``,
"Budgets for .hjif/.ahap content").

A file's cost is bounded before any work that scales with it is done:

- reading: at most :data:`~hapticsdk.interop.hjif_model.MAX_FILE_BYTES` bytes and
  :data:`~hapticsdk.interop.hjif_model.MAX_DEPTH` levels; every check after the JSON parser
  is linear in the number of objects (library references are looked up in an index);
- synthesis and playback hold at most :data:`MAX_OUTPUT_SAMPLES` samples (channels x
  samples) and evaluate at most :data:`MAX_VOICES` effect samples per output sample: the
  work is proportional to the output, whatever the number of overlapping effects;
- sample rates are at most :data:`MAX_SAMPLE_RATE_HZ`;
- keyframes rewritten from out-of-order files: at most :data:`MAX_REORDER_KEYFRAMES` per
  effect (the rewrite is quadratic in them).

Beyond a budget the SDK raises :class:`ContentBudgetError` (a
:class:`~hapticsdk.errors.FormatError`: the CLI prints the field and exits 2) before it
allocates or loops.
"""

from __future__ import annotations

from ..errors import FormatError

#: highest synthesis sample rate (Hz): the finest time step the format expresses, the
#: Main-profile timescale ceiling of MPEG's reference software (48 000 ticks/s)
MAX_SAMPLE_RATE_HZ = 48000.0
#: most samples one synthesis or playback holds (channels x samples): 2^24 float64
#: samples are 128 MiB; a 600 s channel at the DRV2667's 8 kHz is 4.8 M samples
MAX_OUTPUT_SAMPLES = 2 ** 24
#: most effect samples evaluated per output sample (on average over a channel): the
#: format's largest band count per channel (63 at level 2, MPEG's reference conformance
#: check) plus one, each band playing one effect at a time as encoders write them
MAX_VOICES = 64
#: most keyframes of one effect rewritten from file order (the rewrite evaluates the
#: reference's reading at every keyframe: 4096^2 = 2^24 steps)
MAX_REORDER_KEYFRAMES = 4096


class ContentBudgetError(FormatError):
    """Content would cost more time or memory than the SDK's stated budget for it
    (docs/safety.md, "Budgets for .hjif/.ahap content"). ``field`` names the part."""


def check_output(channels: int, samples: int, *, field: str) -> None:
    """Refuse holding ``channels x samples`` samples above :data:`MAX_OUTPUT_SAMPLES`."""
    total = channels * samples
    if total > MAX_OUTPUT_SAMPLES:
        raise ContentBudgetError(
            f"{channels} channel(s) x {samples} samples = {total} samples, above the budget of "
            f"{MAX_OUTPUT_SAMPLES} held at once (docs/safety.md); play or synthesise a shorter stretch", field=field)


def check_work(work: float, field: str, channels: int, samples: int) -> None:
    """Refuse evaluating ``work`` effect samples for ``channels x samples`` output samples
    when that is above :data:`MAX_VOICES` per output sample; ``field`` names the channel
    that costs most."""
    limit = MAX_VOICES * max(1, channels * samples)
    if work > limit:
        raise ContentBudgetError(
            f"overlapping effects: {work:.4g} effect samples for {channels * samples} output samples "
            f"({work / max(1, channels * samples):.4g} per sample), above the budget of {MAX_VOICES} per sample "
            "(docs/safety.md)", field=field)


def check_rate(fs: float, *, field: str) -> None:
    """Refuse sample rates above :data:`MAX_SAMPLE_RATE_HZ`."""
    if fs > MAX_SAMPLE_RATE_HZ:
        raise ContentBudgetError(f"sample rate {fs:g} Hz above the ceiling of {MAX_SAMPLE_RATE_HZ:g} Hz "
                                 "(docs/safety.md)", field=field)

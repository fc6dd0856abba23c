"""Loading plugins reads each distribution's metadata once (issue 30: a render loads ~30
plugins of 5-6 distributions, and each read parses the METADATA file, ~0.3 ms)."""

from __future__ import annotations

from importlib import metadata

from hapticsdk import plugins
from hapticsdk.plugins import registry


def test_each_distribution_metadata_is_parsed_once_per_scan(monkeypatch):
    plugins.refresh()
    reads: list[str] = []
    real = metadata.Distribution.metadata

    def counting(self):
        reads.append(str(getattr(self, "_path", id(self))))
        return real.fget(self)
    monkeypatch.setattr(metadata.Distribution, "metadata", property(counting))
    infos = []
    for kind in ("dimension", "actuator", "solver", "model"):
        reg = registry(kind)
        for name in reg.names():
            if name in reg._local:
                continue
            infos.append(plugins._info(kind, reg._lookup(name)))
    dists = {i.distribution for i in infos}
    assert len(infos) > len(dists) >= 2          # several plugins per distribution
    # each distribution's Name read once (its version reads the metadata once more)
    assert len(reads) <= 2 * len(set(reads)) and len(set(reads)) == len(dists)
    n = len(reads)
    for i in infos[:5]:
        assert plugins._info(i.kind, registry(i.kind)._lookup(i.name)) == i
    assert len(reads) == n                        # answered from the cache
    plugins.refresh()                             # a new scan reads again
    assert plugins._dist_names == {}

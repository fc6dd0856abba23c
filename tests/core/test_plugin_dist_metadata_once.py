"""Loading plugins reads each distribution's metadata once (issue 30: a render loads ~30
plugins of 5-6 distributions, and each read parses the METADATA file, ~0.3 ms); since
round 7 the scan's result is kept between processes (:mod:`hapticsdk.plugin_index`), and
a scan after :func:`hapticsdk.plugins.refresh` reads the metadata again."""

from __future__ import annotations

from importlib import metadata

from hapticsdk import plugin_index, plugins
from hapticsdk.plugins import GROUPS, registry


def test_each_distribution_metadata_is_parsed_once_per_scan(monkeypatch):
    plugins.refresh()                             # the next scan reads the installed files
    reads: list[str] = []
    real = metadata.Distribution.metadata

    def counting(self):
        reads.append(str(getattr(self, "_path", id(self))))
        return real.fget(self)
    monkeypatch.setattr(metadata.Distribution, "metadata", property(counting))
    infos = []
    for kind in GROUPS:
        reg = registry(kind)
        for name in reg.names():
            if name in reg._local:
                continue
            infos.append(plugins._info(kind, reg._lookup(name)))
    dists = {i.distribution for i in infos}
    assert len(infos) > len(dists) >= 2          # several plugins per distribution
    # each distribution's Name read once (its version reads the metadata once more), and
    # the versions the index records (plugin_index.VERSIONS) on top
    assert len(reads) <= 2 * len(set(reads))
    assert len(dists) <= len(set(reads)) <= len(dists) + len(plugin_index.VERSIONS)
    n = len(reads)
    for i in infos[:5]:
        assert plugins._info(i.kind, registry(i.kind)._lookup(i.name)) == i
    assert len(reads) == n                        # answered from the scan
    plugins.refresh()                             # a new scan reads again
    registry("solver").names()
    assert len(reads) > n

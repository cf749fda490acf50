"""The install command of an optional extra follows how sahgrasp was installed."""

from __future__ import annotations

from importlib import metadata
from typing import Any

import pytest

from sahgrasp.bench import extras
from sahgrasp.bench.extras import install_command, is_editable_install


class _Dist:
    def __init__(self, direct_url: str | None) -> None:
        self.direct_url = direct_url

    def read_text(self, name: str) -> str | None:
        return self.direct_url if name == "direct_url.json" else None


@pytest.mark.parametrize(
    ("direct_url", "editable"),
    [
        ('{"dir_info": {"editable": true}, "url": "file:///src/sahgrasp"}', True),
        ('{"dir_info": {}, "url": "file:///src/sahgrasp"}', False),  # pip install .
        (None, False),  # from the package index: no direct_url.json
        ("not json", False),
    ],
)
def test_editable_installs_are_told_apart(
    monkeypatch: pytest.MonkeyPatch, direct_url: str | None, editable: bool
) -> None:
    monkeypatch.setattr(extras.metadata, "distribution", lambda name: _Dist(direct_url))
    assert is_editable_install() is editable
    expected = 'pip install -e ".[bench]"' if editable else 'pip install "sahgrasp[bench]"'
    assert install_command("bench") == expected


def test_a_source_folder_without_install_counts_as_a_checkout(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    def missing(name: str) -> Any:
        raise metadata.PackageNotFoundError(name)

    monkeypatch.setattr(extras.metadata, "distribution", missing)
    assert install_command("sim") == 'pip install -e ".[sim]"'


def test_the_bench_peers_say_the_command_that_fits(monkeypatch: pytest.MonkeyPatch) -> None:
    from sahgrasp.bench import peers

    monkeypatch.setattr(extras.metadata, "distribution", lambda name: _Dist(None))
    monkeypatch.setattr(peers, "_missing_module", lambda modules: modules[0])
    skipped = peers.available_peers(["pink"])[1]
    assert 'install it with pip install "sahgrasp[bench]"' in skipped["pink"]

import pytest

from sahgrasp.model.hand import Hand, load_hand


@pytest.fixture(scope="session")
def sah() -> Hand:
    return load_hand("sah")


@pytest.fixture(scope="session")
def allegro() -> Hand:
    return load_hand("allegro")


@pytest.fixture(scope="session", params=["sah", "allegro"])
def any_hand(request: pytest.FixtureRequest, sah: Hand, allegro: Hand) -> Hand:
    return sah if request.param == "sah" else allegro

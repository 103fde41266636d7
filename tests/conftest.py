import numpy as np
import pytest
from hypothesis import settings

settings.register_profile("adaptrack", deadline=None, max_examples=60, derandomize=True)
settings.load_profile("adaptrack")


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20261122)

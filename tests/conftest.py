import numpy as np
import pytest
from hypothesis import settings

settings.register_profile("adaptrack", deadline=None, max_examples=60, derandomize=True)
settings.load_profile("adaptrack")


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20261122)


@pytest.fixture(scope="session")
def dask_pool():
    """A 2-process dask.distributed LocalCluster, shared by the tests that need one."""
    from adaptrack.parallel import task_pool

    with task_pool(workers=2) as pool:
        yield pool

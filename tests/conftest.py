import pytest

from conform.spec import load_spec


@pytest.fixture(scope="session")
def spec():
    return load_spec()

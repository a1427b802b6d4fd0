import os
import pathlib

import pytest

SCENE = "builtin?triangles=5000"


@pytest.fixture(scope="session")
def cli():
    """The command-line program of the same build, to compare with."""
    path = pathlib.Path(os.environ.get("BVHOPT_BIN_DIR", "build/release")) / "bvhopt"
    if not path.exists():
        pytest.skip("no bvhopt program beside the module")
    return str(path)

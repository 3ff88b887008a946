from pathlib import Path

from ament_pep257.main import main
import pytest


@pytest.mark.linter
@pytest.mark.pep257
def test_pep257():
    package_dir = str(Path(__file__).resolve().parents[1])
    rc = main(argv=[package_dir, 'test'])
    assert rc == 0, 'Found code style errors / warnings'

"""Where the package's shared files (config/, launch/) are, installed or in a source tree."""

from __future__ import annotations

from pathlib import Path
import sys

PACKAGE_NAME = 'grasp_safety_filter'


def share_directory() -> Path:
    """Return the share directory: ament index (ROS), source checkout, or pip's data prefix."""
    try:  # Under ROS 2 the ament index knows the install location.
        from ament_index_python.packages import get_package_share_directory, PackageNotFoundError

        try:
            return Path(get_package_share_directory(PACKAGE_NAME))
        except PackageNotFoundError:
            pass
    except ImportError:
        pass
    source_tree = Path(__file__).resolve().parents[2]
    if (source_tree / 'config').is_dir() and (source_tree / 'package.xml').is_file():
        return source_tree
    return Path(sys.prefix) / 'share' / PACKAGE_NAME


def config_path(name: str = 'paper_scenario.yaml') -> Path:
    """Return a file of the package's config/ directory."""
    return share_directory() / 'config' / name

"""Where the package's shared files (config/, launch/) are, installed or in a source tree."""

from __future__ import annotations

import os
from pathlib import Path
import sys

PACKAGE_NAME = 'grasp_safety_filter'

#: Environment variable through which the ament index finds installed packages.
AMENT_PREFIX_PATH = 'AMENT_PREFIX_PATH'


def share_directory() -> Path:
    """Return the share directory: ament index (ROS), source checkout, or pip's data prefix.

    The ament index is asked only when ``AMENT_PREFIX_PATH`` is set (a sourced ROS or colcon
    workspace): the ``ament_index_python`` that comes with the rclpy wheels raises
    ``OSError`` without it, and a pip-installed package must find its own files anyway.
    """
    if os.environ.get(AMENT_PREFIX_PATH):
        try:
            from ament_index_python.packages import (
                get_package_share_directory,
                PackageNotFoundError,
            )
        except ImportError:
            pass
        else:
            try:
                return Path(get_package_share_directory(PACKAGE_NAME))
            except (PackageNotFoundError, OSError):
                pass  # a workspace without this package: it runs from source or pip
    source_tree = Path(__file__).resolve().parents[2]
    if (source_tree / 'config').is_dir() and (source_tree / 'package.xml').is_file():
        return source_tree
    return Path(sys.prefix) / 'share' / PACKAGE_NAME


def config_path(name: str = 'paper_scenario.yaml') -> Path:
    """Return a file of the package's config/ directory."""
    return share_directory() / 'config' / name

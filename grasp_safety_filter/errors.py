"""The one error type of a user's mistake in a configuration, and how entry points report it.

A parameter file, a ``--set``/``-p`` value, a URDF or an initial grasp that cannot be used
raises a :class:`ConfigError` (or a subclass: ``ParameterError``, ``HandModelError``,
``GraspConfigError``, ``ScenarioError``) whose message names the file, parameter, joint,
link or contact, what was expected and what was received. Exceptions of the libraries that
read such input (YAML, Pinocchio, the OS) are translated where the input is read, never by
catching ``Exception`` at the top. Every entry point (``grasp-demo``, ``grasp-model-report``,
``grasp-bench``, ``grasp-bench-ros``, the three nodes) prints :func:`config_error_line` on
stderr and exits with :data:`EXIT_CONFIG_ERROR`.
"""

from __future__ import annotations

#: Exit code of an entry point that refused its configuration (as argparse's usage errors).
EXIT_CONFIG_ERROR = 2

#: Longest line :func:`config_error_line` prints, characters (a 100k-name list stays readable).
MAX_LINE_LENGTH = 2000


class ConfigError(ValueError):
    """A configuration given by the user cannot be used; the message says why, in words."""


def config_error_line(program: str, error: BaseException | str) -> str:
    """Return ``"<program>: <message>"`` on one line, at most :data:`MAX_LINE_LENGTH` long.

    A message listing several problems on several lines is joined with ``"; "``.
    """
    parts = [part.strip().removeprefix('- ') for part in str(error).splitlines()]
    text = f'{program}: ' + '; '.join(part for part in parts if part).replace(':; ', ': ')
    if len(text) > MAX_LINE_LENGTH:
        text = text[: MAX_LINE_LENGTH - 30] + f'... ({len(text)} characters)'
    return text

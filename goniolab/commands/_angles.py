"""Angle-list arguments of ``goniolab scan`` and ``goniolab predict brdf``.

``--theta-r -40:-30:5`` or ``--theta-r -20:20:1`` is an angle range, not an option:
:func:`allow_negative_angles` widens argparse's test for "negative number" arguments (a
private attribute, stable since Python 3.2) so that lamp-side ranges and lists need no
``--theta-r=`` spelling. The values are parsed by :func:`goniolab.scan.plans.parse_angles`.
"""

from __future__ import annotations

import argparse
import re

__all__ = ["NEGATIVE_ANGLES", "allow_negative_angles"]

#: A negative number, or an angle range/list starting with one ("-40:-30:5", "-10,0,10").
NEGATIVE_ANGLES = re.compile(r"^-\d+$|^-\d*\.\d+$|^-[\d.]+[:,][\d.:,\-]*$")


def allow_negative_angles(parser: argparse.ArgumentParser) -> None:
    """Let ``parser``'s options take values like ``-20:20:1`` and ``-10,0,10``."""
    parser._negative_number_matcher = NEGATIVE_ANGLES

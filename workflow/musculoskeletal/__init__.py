"""Joint moments of the finger: backends (authors' table export, OpenSim model),
response surfaces and patient loads."""

from __future__ import annotations

"""The report's HTML tables (:mod:`.tables`: one table builder per dataset) and
their rule entry points (:mod:`.entry`).  Science-free: it only reformats
datasets the stages wrote.
"""

from __future__ import annotations

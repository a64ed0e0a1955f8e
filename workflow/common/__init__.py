"""What every stage shares: names and code tables (:mod:`.constants`), result
files and their provenance (:mod:`.provenance`), the run log's solve tally
(:mod:`.runlog`), reading the fidelity study's choices (:mod:`.fidelity_choice`),
the .vtu and HTML writers (:mod:`.vtu`, :mod:`.html`) and the MLflow run ledger
(:mod:`.tracking`).  Imports no stage package.
"""

from __future__ import annotations

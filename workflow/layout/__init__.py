"""Stage layout design: the units per group that make the most exercises reachable at the least pressure, searched
on the reduced-order chain and confirmed by the FEA check of the best few (rules/layout.smk; not in the default run).

``search`` is the science (candidates within the bounds, their ranking; pure), ``entry`` reads and writes the files,
``plots`` draws the outcome.
"""

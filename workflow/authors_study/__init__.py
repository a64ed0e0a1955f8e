"""Stage authors' settings: the FEA check of a patient's plans with the authors' published 2D model settings
switched on one at a time, then all together (rules/authors_study.smk; not in the default run).

``settings`` builds each variant's config from the base config (pure), ``summary`` joins the variants' FEA checks into
one dataset (pure), ``plots`` draws it, ``entry`` reads and writes the files.
"""

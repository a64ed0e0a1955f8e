"""The authors' settings as config overrides: one variant per setting, a baseline and all of them together.

The authors' published generator of their 2D finger-actuator model (github.com/sbcglacier/Africomp, read in
``docs/authors_study.md``) differs from the paper's text in several settings; each is written in the config
(``authors_study.settings``) as the keys it overrides. A variant's config is the base config with those keys
replaced, nothing else. Pure functions: no I/O.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from typing import Any

__all__ = [
    "ALL",
    "BASELINE",
    "changed_paths",
    "changes_unit",
    "deep_merge",
    "variant_config",
    "variant_names",
    "variant_overrides",
]

#: The variant that changes nothing (our default model) and the one that changes every setting.
BASELINE = "baseline"
ALL = "all"


def deep_merge(base: Mapping[str, Any], over: Mapping[str, Any]) -> dict[str, Any]:
    """A new mapping: ``base`` with ``over``'s leaves replacing its own (mappings merged key by key, lists replaced)."""
    out = copy.deepcopy(dict(base))
    for k, v in over.items():
        if isinstance(v, Mapping) and isinstance(out.get(k), Mapping):
            out[k] = deep_merge(out[k], v)
        else:
            out[k] = copy.deepcopy(v)
    return out


def _leaves(d: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in d.items():
        path = f"{prefix}.{k}" if prefix else str(k)
        if isinstance(v, Mapping):  # an empty mapping has no leaves
            out.update(_leaves(v, path))
        else:
            out[path] = v
    return out


def changed_paths(base: Mapping[str, Any], other: Mapping[str, Any]) -> list[str]:
    """Dotted paths of the leaves whose values differ between two configs (present in one only counts)."""
    a, b = _leaves(base), _leaves(other)
    return sorted(k for k in a.keys() | b.keys() if a.get(k, object()) != b.get(k, object()))


def variant_names(study: Mapping[str, Any]) -> list[str]:
    """The baseline, each setting in config order, then all together."""
    return [BASELINE, *study["settings"], ALL]


def variant_overrides(study: Mapping[str, Any], name: str) -> dict[str, Any]:
    """The config keys a variant overrides: none, one setting's, or every setting's.

    Raises ``ValueError`` for an unknown name, a setting named like the baseline or ``all``, or two settings that
    override the same key (``all`` would then depend on their order).
    """
    settings = study["settings"]
    clash = {BASELINE, ALL} & set(settings)
    if clash:
        raise ValueError(f"authors_study.settings: {sorted(clash)} is reserved for a variant of the study")
    owner: dict[str, str] = {}
    for s, over in settings.items():
        for path in _leaves(over):
            if path in owner:
                raise ValueError(f"authors_study.settings: {owner[path]} and {s} both set {path}")
            owner[path] = s
    if name == BASELINE:
        return {}
    if name == ALL:
        merged: dict[str, Any] = {}
        for over in settings.values():
            merged = deep_merge(merged, over)
        return merged
    if name not in settings:
        raise ValueError(f"authors_study: no variant {name!r} (known: {', '.join(variant_names(study))})")
    return copy.deepcopy(dict(settings[name]))


def changes_unit(overrides: Mapping[str, Any]) -> bool:
    """Whether a variant changes the actuator unit or its sweep (any ``actuator`` or ``sweep`` key), so that its 2D
    unit sweep and surrogate must be computed again."""
    return bool(overrides.get("actuator")) or bool(overrides.get("sweep"))


def variant_config(config: Mapping[str, Any], name: str) -> dict[str, Any]:
    """The whole config of one variant: the base config with the variant's overrides, and the FEA check's exercises
    set to the study's (``authors_study.exercises``; empty keeps ``fea_check.exercises``)."""
    study = config["authors_study"]
    out = deep_merge(config, variant_overrides(study, name))
    if study.get("exercises"):
        out["fea_check"] = dict(out["fea_check"], exercises=list(study["exercises"]))
    return out

# Config validation, lookup tables and input functions. The only .smk file
# with Python code; the stage files hold nothing but rules.
from pathlib import Path

from snakemake.logging import logger
from snakemake.utils import validate

from workflow import settings
from workflow.authors_study import settings as authors_settings
from workflow.common import fidelity_choice, scheduling
from workflow.common.provenance import code_files, config_sha256

validate(config, "../config/schema.yaml")
# Checks JSON Schema cannot express (cross references between sections),
# still before any job starts; what is computed but questionable is said here.
for _warning in settings.check_config(config):
    logger.warning(f"config: {_warning}")

PATIENTS = sorted(config["patients"])
#: The patients whose plans the default run checks by FEA (fea_check.patients).
CHECKED = settings.checked_patients(config)


wildcard_constraints:
    patient="|".join(PATIENTS) if PATIENTS else "NONE",
    exercise="|".join(config["exercises"]),


def cfg(*keys):
    """The config slice a rule depends on (its hash goes into the outputs)."""
    return {k: config[k] for k in keys if k in config}


def patient_cfg(wildcards):
    """One patient's slice: editing one patient leaves the others alone."""
    return {
        "patient": {wildcards.patient: config["patients"][wildcards.patient]},
        "anthropometry": config["anthropometry"],
        "exercises": config["exercises"],
        "rsm": config["rsm"],
    }


def get_final_output():
    out = [
        "results/doe/ccd.nc",
        "results/doe/scaling.nc",
        "results/validation/scaling.nc",
        "results/musculoskeletal/moments.nc",
        "results/musculoskeletal/rsm.nc",
        "results/musculoskeletal/rsm_r2.png",
    ]
    out += expand("results/patients/{patient}/joint_loads.nc", patient=PATIENTS)
    # OpenSim backend checked against the authors' export (empty when it is absent).
    out += ["results/validation/musculoskeletal.nc", "results/validation/musculoskeletal.png"]
    if config["tracking"]["enabled"]:
        out += expand("results/tracking/{patient}.json", patient=PATIENTS)
    # Nonlinear FEA of the PNA unit.
    out += ["results/actuator/unit_check.nc", "results/actuator/unit_3d_300kpa.vtu"]
    # Pressure sweeps, surrogates and the 2D-to-3D mapping.
    out += expand("results/actuator/response_{fea}.nc", fea=["2d", "3d"])
    out += expand("results/actuator/surrogate_{fea}.joblib", fea=["2d", "3d"])
    out += ["results/actuator/surrogate_cv.nc", "results/actuator/mapping_2d3d.nc"]
    # The unit under an external end moment: FEA at prescribed end rotations vs the unit model.
    out += ["results/actuator/unit_moment_check.nc"]
    # The unit's bending stiffness on and off the diagonal P_T = P_B (FEA of a chain) vs the unit model's is a study of
    # its own (snakemake -c2 stiffness_study, 4.7 min of one core): the FEA check pulls it in when it reads it
    # (fea_check.unit_stiffness, get_check_stiffness).
    # Cascade plans per patient and their validation against Tables 8 and 10.
    out += expand("results/patients/{patient}/cascade_plan.nc", patient=PATIENTS)
    out += ["results/validation/cascade.nc"]
    # The validation patient's plans checked by 2D FEA of the whole actuator on the finger.
    # Its finger section comes from the authors' section points: without them the check is left out, and said so.
    vp = config["cascade"]["validation_patient"]
    # ... and its stand-alone whole actuators in 2D and 3D (Fig. 22; needs no finger).
    out += [f"results/patients/{vp}/standalone_actuator.nc"]
    # The validation patient's and the dummy's plans (fea_check.patients) checked on their own fingers.
    if Path(config["cascade"]["section_points"]).is_file():
        out += expand("results/patients/{patient}/fea_check.nc", patient=CHECKED)
    else:
        logger.warning(
            f"FEA check left out: finger section points {config['cascade']['section_points']} "
            "not found (set cascade.section_points)"
        )
    # Stability maps, speed against accuracy and the report's plots and tables.
    out += ["results/stability/stability.nc", "results/musculoskeletal/moment_angle.png"]
    out += [
        "results/benchmarks/speed_accuracy.nc",
        "results/report/speed_accuracy.html",
        "results/report/fidelity_choices.html",
    ]
    out += expand(
        "results/report/{table}.html",
        table=["scaling", "musculoskeletal", "unit_check", "surrogate_cv", "mapping", "cascade_validation"],
    )
    out += expand("results/patients/{patient}/{table}.html", patient=PATIENTS, table=["joint_loads", "cascade_plan"])
    return out


def get_tracking_inputs(wildcards):
    """Input function: what one patient's ledger row reports (the datasets and plots)."""
    p = wildcards.patient
    out = {
        "scaling": "results/validation/scaling.nc",
        "rsm": "results/musculoskeletal/rsm.nc",
        "rsm_plot": "results/musculoskeletal/rsm_r2.png",
        "loads": f"results/patients/{p}/joint_loads.nc",
        "loads_plot": f"results/patients/{p}/joint_loads.png",
        "plan": f"results/patients/{p}/cascade_plan.nc",
    }
    # a checked patient's row also carries its FEA check; every row the fidelity choice
    if p in CHECKED and Path(config["cascade"]["section_points"]).is_file():
        out["fea_check"] = f"results/patients/{p}/fea_check.nc"
    if fidelity_auto():
        out["fidelity"] = "results/fidelity/fem.nc"
    return out


def moments_source():
    """The backend's moments file that becomes results/musculoskeletal/moments.nc."""
    if config["musculoskeletal"]["backend"] == "opensim":
        return "results/musculoskeletal/moments_opensim.nc"
    return "results/musculoskeletal/moments_table.nc"


def get_patient(wildcards):
    """Param function: one patient's config entry."""
    return config["patients"][wildcards.patient]


# --- Stage surrogates: sweep shards ---------------------------------
def get_sweep_params(wildcards):
    """Param function: one FE model's sweep config (p_max_kpa, n_ratios, n_pressures, n_shards)."""
    return config["sweep"][wildcards.fea]


def get_sweep_slice(wildcards):
    """Param function: the config a sweep of one FE model depends on (its hash goes into the outputs)."""
    return {"sweep": {wildcards.fea: config["sweep"][wildcards.fea]}, "actuator": config.get("actuator", {})}


def get_sweep_shards(wildcards):
    """Input function: the shard files of one FE model's sweep."""
    s = config["sweep"][wildcards.fea]
    n = min(s["n_shards"], s["n_ratios"])
    return expand("results/actuator/sweep/{fea}/shard{shard}.nc", fea=wildcards.fea, shard=range(n))


# --- Stage cascade ----------------------------------------------------
def get_unit_response():
    """Input: the surrogate the cascade plans with (config cascade.surrogate)."""
    return f"results/actuator/surrogate_{config['cascade']['surrogate']}.joblib"


def get_pressure_limit():
    """The silicone's pressure limit and its source (actuator.material): no plan, correction or FEA check exceeds it."""
    m = config["actuator"]["material"]
    return {k: m[k] for k in ("p_limit_kpa", "p_limit_source")}


def get_cascade_slice(wildcards):
    """Param function: the config one patient's plan depends on (its hash goes into the outputs)."""
    return {
        "patient": {wildcards.patient: config["patients"][wildcards.patient]},
        "anthropometry": config["anthropometry"],
        "exercises": config["exercises"],
        "cascade": config["cascade"],
        "unit_model": config["surrogates"]["unit_model"],
        "pressure_limit": get_pressure_limit(),
    }


def get_mapping_slice():
    """The config the 2D-to-3D mapping depends on: the sweeps, the surrogates and the pressure limit."""
    return cfg("sweep", "surrogates") | {"pressure_limit": get_pressure_limit()}


def get_actuator_part(*keys):
    """Only these sections of the actuator config (a rule that uses no more does not rerun on the rest)."""
    return {k: v for k, v in config["actuator"].items() if k in keys}


def get_stability_slice(study, *actuator_keys):
    """The config one stability FE study depends on: its own settings and the actuator sections it uses."""
    return {"stability": {study: config["stability"][study]}, "actuator": get_actuator_part(*actuator_keys)}


def get_maps_slice():
    """The config the stability maps depend on (their labels: meshes, contact, the plans' surrogate, the patients)."""
    return {
        "stability": config["stability"],
        "actuator": get_actuator_part("mesh", "contact"),
        "cascade": {"surrogate": config["cascade"]["surrogate"]},
        "patients": PATIENTS,
    }


def get_validation_patient():
    """The config entry of the patient compared with the paper (cascade.validation_patient)."""
    return config["patients"][config["cascade"]["validation_patient"]]


def get_patient_loads_slice(wildcards):
    """Param function: one patient's loads depend on its slice and, with fidelity.auto, the study's tolerance."""
    fid = config["fidelity"]
    extra = (
        {"fidelity": {"tolerance": fid["tolerance"]["msk_rel"], "scaling": config["scaling"]}} if fid["auto"] else {}
    )
    return patient_cfg(wildcards) | extra


def get_validation_plans(wildcards):
    """Input function: the plan compared with Table 8 (the mean finger) and, if configured, the dummy's (Table 10)."""
    c = config["cascade"]
    out = {"plan": f"results/patients/{c['validation_patient']}/cascade_plan.nc"}
    if c.get("dummy_patient"):
        out["dummy_plan"] = f"results/patients/{c['dummy_patient']}/cascade_plan.nc"
    return out


# --- Stage FEA check -------------------------------------------------
def get_fea_exercises():
    """The exercises the FEA check runs (config fea_check.exercises, else all)."""
    return list(config["fea_check"]["exercises"] or config["exercises"])


def get_standalone_parts(wildcards):
    """Input function: one stand-alone result per exercise of the study (fea_check.standalone.exercises, else the
    check's)."""
    exercises = config["fea_check"].get("standalone", {}).get("exercises") or get_fea_exercises()
    return expand("results/patients/{patient}/standalone/{exercise}.nc", patient=wildcards.patient, exercise=exercises)


def get_fea_surrogates(wildcards):
    """Input function: both surrogates (the 2D-to-3D mapping of the plan's pressures, the reduced-order
    chains of the 2D-unit prediction and of the correction step)."""
    return {f"surrogate_{f}": f"results/actuator/surrogate_{f}.joblib" for f in ("2d", "3d")}


def get_check_stiffness(wildcards):
    """Input function: the unit's measured stiffness table when fea_check.unit_stiffness is on (the check's 2D
    chain takes it near P_T = P_B), else nothing."""
    return {"unit_stiffness": "results/actuator/unit_stiffness.nc"} if config["fea_check"].get("unit_stiffness") else {}


def get_calibration_patient():
    """Whose finger the chain's calibration runs on (cascade.calibration.patient, else the validation patient)."""
    c = config["cascade"]
    return c["calibration"].get("patient") or c["validation_patient"]


def cascade_cfg_without(*keys):
    """The cascade section without ``keys`` and without whether the plans use the chain's calibration: what a rule
    reads that takes its chain from its inputs (an FEA check from its plan, a layout plan from layout.calibrated) or
    runs upstream of the calibration, so that switching cascade.calibration.use reruns only the plans it changes."""
    c = {k: v for k, v in config["cascade"].items() if k not in keys}
    c["calibration"] = {k: v for k, v in c["calibration"].items() if k != "use"}
    return c


def calibration_cascade_cfg():
    """The cascade section as the chain's calibration reads it: without the planner and without whether the plans
    use the calibration, so that switching either does not rerun its FEA."""
    return cascade_cfg_without("planner", "stiffness_margin")


def get_calibration_slice(wildcards):
    """Param function: the config the chain's calibration depends on (not the plans': it runs upstream of them)."""
    name = get_calibration_patient()
    return {
        "patient": {name: config["patients"][name]},
        "anthropometry": config["anthropometry"],
        "cascade": calibration_cascade_cfg(),
        "unit_model": config["surrogates"]["unit_model"],
        "actuator": config["actuator"],
        "fea_check": fea_check_cfg(),
    }


def get_chain_calibration(wildcards):
    """Input function: the chain's calibration, when the plans use it (cascade.calibration.use)."""
    if config["cascade"]["calibration"]["use"]:
        return {"calibration": "results/validation/chain_calibration.nc"}
    return {}


def check_keys(fea_check):
    """A fea_check section as an FEA check reads it: not which patients the default run checks, nor the stand-alone
    actuator's settings (rule standalone_exercise's), so that editing those reruns no check."""
    return {k: v for k, v in fea_check.items() if k not in ("patients", "standalone")}


def fea_check_cfg():
    """The config's fea_check section as an FEA check reads it (see check_keys)."""
    return check_keys(config["fea_check"])


def get_fea_check_slice(wildcards):
    """Param function: the config one patient's FEA check depends on."""
    return get_cascade_slice(wildcards) | {
        "cascade": cascade_cfg_without(),
        "actuator": config["actuator"],
        "fea_check": fea_check_cfg(),
    }


def get_standalone_slice(wildcards):
    """Param function: the config one stand-alone exercise depends on (the check's and the stand-alone settings)."""
    return get_fea_check_slice(wildcards) | {"fea_check": config["fea_check"]}


def get_fea_check_rule_slice(wildcards):
    """Param function: the check's slice and the tolerance that judges it."""
    return get_fea_check_slice(wildcards) | {"check_tolerance_deg": config["fidelity"]["tolerance"]["check_deg"]}


def get_check_study_slice(wildcards):
    """Param function: the check's slice and the mesh study's settings (fidelity.check; with the coarsest-first
    search, the tolerance and penetration bound that decide where it stops)."""
    out = {**get_fea_check_slice(wildcards), "check": config["fidelity"]["check"]}
    if config["fidelity"]["check"].get("search", "coarsest_first") != "all":
        out["check_tolerance_deg"] = config["fidelity"]["tolerance"]["check_deg"]
        out["penetration_bound_mm"] = config["fea_check"]["penetration_bound_mm"]
    return out


def get_fem_case_slice(wildcards):
    """Param function: one FE case of the fidelity study depends on the unit config and the study points (and, where
    it shares the sweep's P_B = 0 ray, on that ray's samples)."""
    return {
        "case": wildcards.case,
        "actuator": config["actuator"],
        "p_top_kpa": config["fidelity"]["p_top_kpa"],
        "iteration_budget": config["fidelity"]["fem_iteration_budget"],
        "sweep": get_fem_case_sweep(wildcards),
    }


def get_fem_case_sweep(wildcards):
    """Param function: the sweep config the FE case lands its steps on ({}: none; workflow.common.fidelity_choice.case_sweep)."""
    case = fidelity_choice.FemCase.parse(wildcards.case)
    cases = fidelity_choice.fem_cases(config["fidelity"]["fem_cases"])
    sweep = config["sweep"][case.model]
    return fidelity_choice.case_sweep(case, cases, sweep, config["fidelity"]["p_top_kpa"], fidelity_auto())


def get_fem_tolerances():
    """The FE study's relative tolerances of the free angle and the blocked moment."""
    return {q: config["fidelity"]["tolerance"][f"fem_{q}_rel"] for q in ("angle", "moment")}


def get_fem_choice_slice():
    """The config the FE study's choice depends on."""
    return {"fidelity": {k: config["fidelity"][k] for k in ("fem_cases", "p_top_kpa", "tolerance")}}


# --- Stage fidelity -----------------------------------
FEM_CASES = [c.name for c in fidelity_choice.fem_cases(config["fidelity"]["fem_cases"])]


def fem_case_priority(wildcards):
    """Queue priority of an FE study case: the longest first (workflow.common.scheduling)."""
    return scheduling.fem_case_priority(fidelity_choice.FemCase.parse(wildcards.case))


def sweep_shard_priority(wildcards):
    """Queue priority of a sweep shard: ahead of the studies nothing waits for, the longest 3D rays first."""
    return scheduling.sweep_shard_priority(
        wildcards.fea, int(wildcards.shard), int(config["sweep"][wildcards.fea]["n_shards"])
    )


def fidelity_auto():
    return bool(config["fidelity"]["auto"])


def get_fem_choice(wildcards):
    """Input function: the FE study's choice of mesh, when fidelity.auto picks it."""
    return {"fidelity": "results/fidelity/fem.nc"} if fidelity_auto() else {}


def get_fem_cases(wildcards):
    """Input function: the FE study's cases, when fidelity.auto picks the mesh: the unit check reads the chosen
    case's rays and the sweep its P_B = 0 ray instead of solving them again (the study ran them on the same mesh and
    config)."""
    return {"cases": expand("results/fidelity/fem/{case}.nc", case=FEM_CASES)} if fidelity_auto() else {}


def get_opensim_model(wildcards):
    """Input function: the reference OpenSim model, when the backend has one (direct sampling)."""
    if config["musculoskeletal"]["backend"] == "opensim":
        return {"model": "results/musculoskeletal/opensim/finger_reference.osim"}
    return {}


def get_msk_choice(wildcards):
    """Input function: the musculoskeletal study (and model) a patient's loads choose from, when fidelity.auto."""
    return (
        {"msk_study": "results/fidelity/musculoskeletal.nc", **get_opensim_model(wildcards)} if fidelity_auto() else {}
    )


def get_check_choice(wildcards):
    """Input function: the FEA-check mesh study, when fidelity.auto picks the check's mesh. The study runs on the
    validation patient; every patient's check takes its choice (one study, not one per patient)."""
    vp = config["cascade"]["validation_patient"]
    return {"check_study": f"results/patients/{vp}/fidelity_check.nc"} if fidelity_auto() else {}


def get_speed_accuracy_inputs(wildcards):
    """Input function: the validation patient's plan inputs and check study (when the section points exist)."""
    vp = config["cascade"]["validation_patient"]
    out = {
        "joint_loads": f"results/patients/{vp}/joint_loads.nc",
        "moments_all": "results/musculoskeletal/moments.nc",
        "ccd": "results/doe/ccd.nc",
    }
    if Path(config["cascade"]["section_points"]).is_file():
        out["check"] = f"results/patients/{vp}/fidelity_check.nc"
    return out


def get_fidelity_choice_inputs(wildcards):
    """Input function: the outputs whose attrs say which fidelity they used (unit check, responses,
    surrogate CV, every patient's loads, the validation patient's FEA check)."""
    out = {
        "unit_check": "results/actuator/unit_check.nc",
        "cv": "results/actuator/surrogate_cv.nc",
        "responses": expand("results/actuator/response_{fea}.nc", fea=["2d", "3d"]),
        "loads": expand("results/patients/{patient}/joint_loads.nc", patient=PATIENTS),
    }
    if Path(config["cascade"]["section_points"]).is_file():
        out["fea_check"] = f"results/patients/{config['cascade']['validation_patient']}/fea_check.nc"
    return out


# --- Stage reporting --------------------------------------------------
#: The datasets the report shows as tables, by table name.
REPORT_DATASETS = {
    "scaling": "results/validation/scaling.nc",
    "musculoskeletal": "results/validation/musculoskeletal.nc",
    "unit_check": "results/actuator/unit_check.nc",
    "surrogate_cv": "results/actuator/surrogate_cv.nc",
    "mapping": "results/actuator/mapping_2d3d.nc",
    "cascade_validation": "results/validation/cascade.nc",
}


def get_report_dataset(wildcards):
    """Input function: the dataset behind one report table."""
    return REPORT_DATASETS[wildcards.table]


# --- Stage authors' settings (not in the default run) -------------------

AUTHORS_VARIANTS = authors_settings.variant_names(config["authors_study"])
_AUTHORS_CONFIGS = {v: authors_settings.variant_config(config, v) for v in AUTHORS_VARIANTS}
# every variant is a config of its own: checked like the base config, before any job starts
for _v, _c in _AUTHORS_CONFIGS.items():
    try:
        validate(_c, "../config/schema.yaml")
        settings.check_config(_c)
    except Exception as _err:
        raise ValueError(f"authors_study variant {_v}: {_err}") from None
#: the variants that change the unit (silicone, section, paper): their 2D sweep and surrogate run again
AUTHORS_UNIT_VARIANTS = [
    v
    for v in AUTHORS_VARIANTS
    if authors_settings.changes_unit(authors_settings.variant_overrides(config["authors_study"], v))
]


def authors_config(variant):
    """One variant's whole config (the base config with the variant's overrides)."""
    return _AUTHORS_CONFIGS[variant]


def authors_patient():
    """Whose plans the study checks (authors_study.patient, else the validation patient)."""
    return config["authors_study"]["patient"] or config["cascade"]["validation_patient"]


def authors_section(*keys):
    """Param function: a variant's config section (keys nested, e.g. "surrogates", "unit_model")."""

    def get(wildcards):
        out = authors_config(wildcards.variant)
        for k in keys:
            out = out[k]
        return out

    return get


def get_authors_pressure_limit(wildcards):
    """Param function: a variant's silicone pressure limit and its source."""
    m = authors_config(wildcards.variant)["actuator"]["material"]
    return {k: m[k] for k in ("p_limit_kpa", "p_limit_source")}


def authors_surrogate(variant, fea):
    """A variant's surrogate: its own 2D one where it changes the unit, else the default run's."""
    if fea == "2d" and variant in AUTHORS_UNIT_VARIANTS:
        return f"results/authors_study/{variant}/surrogate_2d.joblib"
    return f"results/actuator/surrogate_{fea}.joblib"


def get_authors_surrogates(wildcards):
    """Input function: both surrogates of a variant's FEA check."""
    return {f"surrogate_{f}": authors_surrogate(wildcards.variant, f) for f in ("2d", "3d")}


def get_authors_sweep_shards(wildcards):
    """Input function: the shard files of a variant's 2D unit sweep."""
    s = authors_config(wildcards.variant)["sweep"]["2d"]
    n = min(s["n_shards"], s["n_ratios"])
    return expand("results/authors_study/{variant}/sweep/2d/shard{shard}.nc", variant=wildcards.variant, shard=range(n))


def get_authors_slice(kind):
    """Param function: the config a variant's job depends on, as the default run's rule of that ``kind`` (sweep,
    plan, check) takes it from the variant's config (its hash goes into the outputs)."""

    def get(wildcards):
        c = authors_config(wildcards.variant)
        if kind == "sweep":
            return {"sweep": {"2d": c["sweep"]["2d"]}, "actuator": c["actuator"]}
        name = wildcards.patient
        out = {
            "patient": {name: c["patients"][name]},
            "anthropometry": c["anthropometry"],
            "exercises": c["exercises"],
            "cascade": c["cascade"],
            "unit_model": c["surrogates"]["unit_model"],
            "pressure_limit": {k: c["actuator"]["material"][k] for k in ("p_limit_kpa", "p_limit_source")},
        }
        if kind == "check":
            out |= {"actuator": c["actuator"], "fea_check": check_keys(c["fea_check"])}
        return out

    return get


def get_authors_checks():
    """Input: every variant's FEA check of the study patient."""
    return expand(
        "results/authors_study/{variant}/{patient}/fea_check.nc", variant=AUTHORS_VARIANTS, patient=authors_patient()
    )


def get_authors_changes():
    """Param: per variant the config keys it changes against the baseline (dotted), for the study's table."""
    base = authors_config(authors_settings.BASELINE)
    return {v: authors_settings.changed_paths(base, authors_config(v)) for v in AUTHORS_VARIANTS}


# --- Stage layout design (not in the default run) -------------------------
def get_layout_calibration(wildcards):
    """Input function: the chain's calibration, when the layout search runs on it (layout.calibrated)."""
    return {"calibration": "results/validation/chain_calibration.nc"} if config["layout"]["calibrated"] else {}


def get_layout_choice(wildcards):
    """Input function: a designed patient's chosen layout, when its plan uses it (layout.use)."""
    lay = config["layout"]
    if lay["use"] and wildcards.patient in lay["patients"]:
        return {"layout": f"results/patients/{wildcards.patient}/layout.nc"}
    return {}


def layout_search_cfg():
    """The layout section as the search reads it (not which patients, how many to check, or whether plans use it)."""
    return {
        k: config["layout"][k]
        for k in ("bounds", "max_length_mm", "max_mass_g", "max_overhang_mm", "max_candidates", "calibrated")
    }


def get_layout_rank(wildcards):
    """Param function: the search rank whose layout a layout plan takes (None: the default layout's plan)."""
    rank = getattr(wildcards, "rank", None)
    return None if rank is None else int(rank)


def get_layout_plan_slice(wildcards):
    """Param function: the config a layout plan depends on (the default plan's, on the layout search's chain, and
    the rank it takes from the search)."""
    out = get_cascade_slice(wildcards) | {"cascade": cascade_cfg_without()}
    rank = get_layout_rank(wildcards)
    return out if rank is None else out | {"layout_rank": rank}


def get_layout_slice(wildcards):
    """Param function: the config the layout search depends on."""
    return get_layout_plan_slice(wildcards) | {"layout": layout_search_cfg()}


def layout_plan_inputs(ranked):
    """Input function of a layout plan: the default plan's inputs on the chain the layout search ranks on, and with
    ``ranked`` the search, whose rank-k layout the plan takes."""

    def inputs(wildcards):
        response = get_unit_response()
        out = get_layout_calibration(wildcards) | {
            "unit_response": response,
            "response": response.replace("surrogate_", "response_").replace(".joblib", ".nc"),
            "ccd": "results/doe/ccd.nc",
            "moments": "results/musculoskeletal/moments.nc",
            "joint_loads": f"results/patients/{wildcards.patient}/joint_loads.nc",
            "code": code_files("scripts.cascade_plan"),
        }
        if ranked:
            out["layout"] = f"results/patients/{wildcards.patient}/layout/search.nc"
        return out

    return inputs


def get_layout_checks(wildcards):
    """Input function: the FEA checks of the chain's best layouts of one patient, and of the length rule's layout
    with its plan (layout.check_default)."""
    lay, base = config["layout"], f"results/patients/{wildcards.patient}/layout"
    out = {"checks": [f"{base}/top{k}/fea_check.nc" for k in range(lay["confirm_top"])]}
    if lay["check_default"]:
        out |= {"default_plan": f"{base}/default/cascade_plan.nc", "default_check": f"{base}/default/fea_check.nc"}
    return out

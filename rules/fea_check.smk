# Stage FEA check: every plan checked by a 2D plane-strain FEA of the
# whole actuator strapped to the patient's finger (paper Fig. 18-21), and the
# stand-alone whole actuator in 2D and 3D (Fig. 22). Entry points in
# workflow/fea_check/entry.py; the FE models in workflow/fem. Input functions live in rules/common.smk:
#   get_fea_exercises()      -> the exercises checked (config fea_check.exercises or all)
#   get_fea_surrogates()     -> {"surrogate_2d": ..., "surrogate_3d": ...}
#   get_check_stiffness()    -> {"unit_stiffness": ...} when fea_check.unit_stiffness, else {}
#   get_fea_check_slice(wc)  -> the config a patient's check depends on
#   get_standalone_parts(wc) -> the stand-alone exercises solved apart (one job each: two 3D solves run at once)
#   CHECKED                  -> the patients the default run checks (fea_check.patients); check_<patient> for any
#   get_calibration_patient() -> whose finger the chain's calibration runs on (cascade.calibration.patient)


rule fea_check:
    input:
        unpack(get_fea_surrogates),
        unpack(get_check_choice),
        unpack(get_check_stiffness),
        plan="results/patients/{patient}/cascade_plan.nc",
        ccd="results/doe/ccd.nc",
        moments="results/musculoskeletal/moments.nc",
        joint_loads="results/patients/{patient}/joint_loads.nc",
        code=code_files("scripts.fea_check"),
    output:
        nc="results/patients/{patient}/fea_check.nc",
        vtu=expand("results/patients/{{patient}}/fea_check_{exercise}.vtu", exercise=get_fea_exercises()),
        plot=report(
            "results/patients/{patient}/fea_check.png",
            caption="../report/fea_check.rst",
            category="FEA check",
            subcategory="{patient}",
        ),
    log:
        "logs/fea_check/fea_check/{patient}.log",
    benchmark:
        "results/benchmarks/rules/fea_check_{patient}.tsv"
    priority: scheduling.CHECK_PRIORITY  # the run's last jobs (workflow/common/scheduling.py)
    conda:
        "../envs/project.yaml"
    params:
        patient=get_patient,
        fea_check=fea_check_cfg(),
        actuator=config["actuator"],
        cascade=cascade_cfg_without(),
        anthropometry=config["anthropometry"],
        unit_model=config["surrogates"]["unit_model"],
        tolerance_deg=config["fidelity"]["tolerance"]["check_deg"],
        config_slice=get_fea_check_rule_slice,
    script:
        "../workflow/scripts/fea_check.py"


rule standalone_exercise:
    input:
        unpack(get_fea_surrogates),
        plan="results/patients/{patient}/cascade_plan.nc",
        code=code_files("scripts.standalone_exercise"),
    output:
        nc="results/patients/{patient}/standalone/{exercise}.nc",
    log:
        "logs/fea_check/standalone_exercise/{patient}_{exercise}.log",
    benchmark:
        "results/benchmarks/rules/standalone_exercise_{patient}_{exercise}.tsv"
    conda:
        "../envs/project.yaml"
    params:
        fea_check=config["fea_check"],
        actuator=config["actuator"],
        cascade=cascade_cfg_without(),
        config_slice=get_standalone_slice,
    script:
        "../workflow/scripts/standalone_exercise.py"


rule standalone_actuator:
    input:
        parts=get_standalone_parts,
        code=code_files("scripts.standalone_actuator"),
    output:
        nc="results/patients/{patient}/standalone_actuator.nc",
        plot=report(
            "results/patients/{patient}/standalone_actuator.png",
            caption="../report/standalone_actuator.rst",
            category="FEA check",
            subcategory="{patient}",
        ),
    log:
        "logs/fea_check/standalone_actuator/{patient}.log",
    benchmark:
        "results/benchmarks/rules/standalone_actuator_{patient}.tsv"
    conda:
        "../envs/project.yaml"
    params:
        config_slice=get_fea_check_slice,
    script:
        "../workflow/scripts/standalone_actuator.py"


# The reduced-order chain calibrated to the 2D FEA at pressure sets fixed in advance (upstream of the plans: it
# needs no plan). The plans use it with cascade.calibration.use; alone: snakemake -c2 calibrate_chain.
rule chain_calibration:
    input:
        unpack(get_fea_surrogates),
        ccd="results/doe/ccd.nc",
        moments="results/musculoskeletal/moments.nc",
        joint_loads=f"results/patients/{get_calibration_patient()}/joint_loads.nc",
        table08="resources/table08_planned_pressures_3d.csv",
        code=code_files("scripts.chain_calibration"),
    output:
        nc="results/validation/chain_calibration.nc",
        plot=report(
            "results/validation/chain_calibration.png",
            caption="../report/chain_calibration.rst",
            category="FEA check",
        ),
    log:
        "logs/fea_check/chain_calibration.log",
    benchmark:
        "results/benchmarks/rules/chain_calibration.tsv"
    conda:
        "../envs/project.yaml"
    params:
        patient_name=get_calibration_patient(),
        patient=config["patients"][get_calibration_patient()],
        calibration=calibration_cascade_cfg()["calibration"],
        fea_check=fea_check_cfg(),
        actuator=config["actuator"],
        cascade=calibration_cascade_cfg(),
        anthropometry=config["anthropometry"],
        unit_model=config["surrogates"]["unit_model"],
        config_slice=get_calibration_slice,
    script:
        "../workflow/scripts/chain_calibration.py"


rule calibrate_chain:
    input:
        "results/validation/chain_calibration.nc",
    localrule: True


# One target per patient (snakemake -c2 check_<patient>): the default run checks fea_check.patients only.
for _patient in PATIENTS:

    rule:
        name:
            f"check_{_patient}"
        input:
            f"results/patients/{_patient}/fea_check.nc",
        localrule: True

# Stage fidelity: speed against accuracy of every
# fidelity the workflow offers, and, with fidelity.auto on, the cheapest one
# that meets the stated tolerance per stage (the sweeps and the unit check take
# the FE mesh chosen here, the patients' loads the response surfaces or direct
# OpenSim sampling, the FEA check its mesh). Entry points in workflow/fidelity/entry.py
# and entry_fem.py (the FE cases, on their own so judging the study does not rerun its FEA).
# Input functions live in rules/common.smk:
#   FEM_CASES               -> the FE unit cases of fidelity.fem_cases (names)
#   fem_case_priority(wc)   -> a case's queue priority, the longest case first
#   get_fem_choice(wc)      -> {"fidelity": results/fidelity/fem.nc} when fidelity.auto, else {}
#   get_msk_choice(wc)      -> the musculoskeletal study (+ OpenSim model) when fidelity.auto
#   get_check_choice(wc)    -> the patient's check study when fidelity.auto


rule fidelity_fem:
    input:
        code=code_files("scripts.fidelity_fem"),
    output:
        "results/fidelity/fem/{case}.nc",
    log:
        "logs/fidelity/fidelity_fem/{case}.log",
    benchmark:
        "results/benchmarks/rules/fidelity_fem_{case}.tsv"
    wildcard_constraints:
        case=r"fem_(2d|3d)_h[0-9.]+_(contact|nocontact)",
    # first in the queue, the longest case first: every sweep waits for the study's mesh choice, so its cases are
    # the cold run's critical path
    priority: fem_case_priority
    conda:
        "../envs/project.yaml"
    params:
        actuator=config["actuator"],
        p_top_kpa=config["fidelity"]["p_top_kpa"],
        iteration_budget=config["fidelity"]["fem_iteration_budget"],
        sweep=get_fem_case_sweep,
        config_slice=get_fem_case_slice,
    script:
        "../workflow/scripts/fidelity_fem.py"


rule fidelity_fem_choice:
    input:
        cases=expand("results/fidelity/fem/{case}.nc", case=FEM_CASES),
        code=code_files("scripts.fidelity_fem_choice"),
    output:
        "results/fidelity/fem.nc",
    log:
        "logs/fidelity/fidelity_fem_choice.log",
    benchmark:
        "results/benchmarks/rules/fidelity_fem_choice.tsv"
    conda:
        "../envs/project.yaml"
    params:
        tolerance=get_fem_tolerances(),
        config_slice=get_fem_choice_slice(),
    script:
        "../workflow/scripts/fidelity_fem_choice.py"


rule fidelity_msk:
    input:
        unpack(get_opensim_model),
        ccd="results/doe/ccd.nc",
        moments="results/musculoskeletal/moments.nc",
        rsm="results/musculoskeletal/rsm.nc",
        code=code_files("scripts.fidelity_msk"),
    output:
        "results/fidelity/musculoskeletal.nc",
    log:
        "logs/fidelity/fidelity_msk.log",
    benchmark:
        "results/benchmarks/rules/fidelity_msk.tsv"
    conda:
        "../envs/project.yaml"
    params:
        points=config["fidelity"]["msk_points"],
        exercises=config["exercises"],
        scaling=config["scaling"],
        anthropometry=config["anthropometry"],
        config_slice=cfg("exercises", "scaling", "anthropometry", "musculoskeletal", "rsm")
        | {"msk_points": config["fidelity"]["msk_points"]},
    script:
        "../workflow/scripts/fidelity_msk.py"


rule fidelity_check:
    input:
        unpack(get_fea_surrogates),
        plan="results/patients/{patient}/cascade_plan.nc",
        ccd="results/doe/ccd.nc",
        moments="results/musculoskeletal/moments.nc",
        joint_loads="results/patients/{patient}/joint_loads.nc",
        code=code_files("scripts.fidelity_check"),
    output:
        "results/patients/{patient}/fidelity_check.nc",
    log:
        "logs/fidelity/fidelity_check/{patient}.log",
    benchmark:
        "results/benchmarks/rules/fidelity_check_{patient}.tsv"
    # the FEA checks, the run's last jobs, wait for this mesh choice (workflow/common/scheduling.py)
    priority: scheduling.CHECK_PRIORITY
    conda:
        "../envs/project.yaml"
    params:
        patient=get_patient,
        check=config["fidelity"]["check"],
        # coarsest_first stops at the first mesh within this tolerance of the finest (what the check's choice asks)
        tolerance_deg=config["fidelity"]["tolerance"]["check_deg"],
        penetration_bound_mm=config["fea_check"]["penetration_bound_mm"],
        fea_check=fea_check_cfg(),
        actuator=config["actuator"],
        cascade=cascade_cfg_without(),
        anthropometry=config["anthropometry"],
        unit_model=config["surrogates"]["unit_model"],
        config_slice=get_check_study_slice,
    script:
        "../workflow/scripts/fidelity_check.py"


rule speed_accuracy:
    input:
        unpack(get_speed_accuracy_inputs),
        fem="results/fidelity/fem.nc",
        response_2d="results/actuator/response_2d.nc",
        response_3d="results/actuator/response_3d.nc",
        cv="results/actuator/surrogate_cv.nc",
        msk="results/fidelity/musculoskeletal.nc",
        code=code_files("scripts.speed_accuracy"),
    output:
        nc="results/benchmarks/speed_accuracy.nc",
        plot=report(
            "results/benchmarks/speed_accuracy.png",
            caption="../report/speed_accuracy.rst",
            category="Speed and accuracy",
        ),
    log:
        "logs/fidelity/speed_accuracy.log",
    benchmark:
        "results/benchmarks/rules/speed_accuracy.tsv"
    conda:
        "../envs/project.yaml"
    params:
        surrogates=config["surrogates"],
        patient=get_validation_patient(),
        cascade=config["cascade"],
        anthropometry=config["anthropometry"],
        unit_model=config["surrogates"]["unit_model"],
        config_slice=cfg("fidelity", "surrogates", "cascade"),
    script:
        "../workflow/scripts/speed_accuracy.py"


rule speed_accuracy_table:
    input:
        dataset="results/benchmarks/speed_accuracy.nc",
        code=code_files("scripts.report_table"),
    output:
        report(
            "results/report/speed_accuracy.html",
            caption="../report/speed_accuracy_table.rst",
            category="Speed and accuracy",
        ),
    log:
        "logs/report/speed_accuracy_table.log",
    benchmark:
        "results/benchmarks/rules/speed_accuracy_table.tsv"
    conda:
        "../envs/project.yaml"
    params:
        table="speed_accuracy",
    script:
        "../workflow/scripts/report_table.py"


rule fidelity_choices:
    input:
        unpack(get_fidelity_choice_inputs),
        code=code_files("scripts.fidelity_choices"),
    output:
        report(
            "results/report/fidelity_choices.html",
            caption="../report/fidelity_choices.rst",
            category="Speed and accuracy",
        ),
    log:
        "logs/report/fidelity_choices.log",
    benchmark:
        "results/benchmarks/rules/fidelity_choices.tsv"
    conda:
        "../envs/project.yaml"
    script:
        "../workflow/scripts/fidelity_choices.py"

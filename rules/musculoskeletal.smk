# Stage musculoskeletal (sections 2.2-2.3): joint moments at the CCD runs (the
# authors' export or our OpenSim finger model, scaled per run and sampled into
# moment-angle curves), response surfaces with ANOVA, patient loads.
# Entry points in workflow/musculoskeletal/entry.py and entry_opensim.py.


rule joint_moments_table:
    input:
        ccd="results/doe/ccd.nc",
        table=config["musculoskeletal"]["table_path"],
        code=code_files("scripts.joint_moments_table"),
    output:
        "results/musculoskeletal/moments_table.nc",
    log:
        "logs/musculoskeletal/joint_moments_table.log",
    benchmark:
        "results/benchmarks/rules/joint_moments_table.tsv"
    conda:
        "../envs/project.yaml"
    script:
        "../workflow/scripts/joint_moments_table.py"


rule joint_moments:
    input:
        source=moments_source(),
        code=code_files("scripts.joint_moments"),
    output:
        "results/musculoskeletal/moments.nc",
    log:
        "logs/musculoskeletal/joint_moments.log",
    benchmark:
        "results/benchmarks/rules/joint_moments.tsv"
    conda:
        "../envs/project.yaml"
    params:
        backend=config["musculoskeletal"]["backend"],
    script:
        "../workflow/scripts/joint_moments.py"


rule rsm:
    input:
        ccd="results/doe/ccd.nc",
        moments="results/musculoskeletal/moments.nc",
        code=code_files("scripts.rsm"),
    output:
        rsm="results/musculoskeletal/rsm.nc",
        plot=report("results/musculoskeletal/rsm_r2.png", caption="../report/rsm.rst", category="Musculoskeletal"),
    log:
        "logs/musculoskeletal/rsm.log",
    benchmark:
        "results/benchmarks/rules/rsm.tsv"
    conda:
        "../envs/project.yaml"
    params:
        exercises=config["exercises"],
        alpha=config["rsm"]["alpha"],
    script:
        "../workflow/scripts/rsm.py"


rule patient_loads:
    input:
        unpack(get_msk_choice),
        ccd="results/doe/ccd.nc",
        moments="results/musculoskeletal/moments.nc",
        rsm="results/musculoskeletal/rsm.nc",
        code=code_files("scripts.patient_loads"),
    output:
        loads="results/patients/{patient}/joint_loads.nc",
        plot=report(
            "results/patients/{patient}/joint_loads.png",
            caption="../report/joint_loads.rst",
            category="Patients",
            subcategory="{patient}",
        ),
    log:
        "logs/patients/{patient}/patient_loads.log",
    benchmark:
        "results/benchmarks/rules/patient_loads_{patient}.tsv"
    conda:
        "../envs/project.yaml"
    params:
        patient=get_patient,
        exercises=config["exercises"],
        anthropometry=config["anthropometry"],
        prediction_alpha=config["rsm"]["prediction_alpha"],
        tolerance=config["fidelity"]["tolerance"]["msk_rel"],
        scaling=config["scaling"],
        config_slice=get_patient_loads_slice,
    script:
        "../workflow/scripts/patient_loads.py"


rule opensim_model:
    input:
        parameters=config["opensim"]["parameters"],
        scaling="results/doe/scaling.nc",
        code=code_files("scripts.opensim_model"),
    output:
        "results/musculoskeletal/opensim/finger_reference.osim",
    log:
        "logs/opensim/opensim_model.log",
    benchmark:
        "results/benchmarks/rules/opensim_model.tsv"
    conda:
        "../envs/project.yaml"
    params:
        fingers=config["opensim"]["fingers"],
        reference_marker=config["opensim"]["reference_marker"],
    script:
        "../workflow/scripts/opensim_model.py"


rule opensim_sample:
    input:
        model="results/musculoskeletal/opensim/finger_reference.osim",
        scaling="results/doe/scaling.nc",
        code=code_files("scripts.opensim_sample"),
    output:
        "results/musculoskeletal/opensim/run{run}.nc",
    log:
        "logs/opensim/opensim_sample_{run}.log",
    benchmark:
        "results/benchmarks/rules/opensim_sample_{run}.tsv"
    wildcard_constraints:
        run=r"\d+",
    conda:
        "../envs/project.yaml"
    params:
        fingers=config["opensim"]["fingers"],
        angle_step_deg=config["opensim"]["angle_step_deg"],
        activations=config["opensim"]["activations"],
        include_gravity=config["opensim"]["include_gravity"],
        config_slice=cfg("opensim", "scaling", "anthropometry", "design"),
    script:
        "../workflow/scripts/opensim_sample.py"


rule opensim_merge:
    input:
        # A three-factor CCD has 15 runs (2^3 corners, 6 axial points, the centre).
        runs=expand("results/musculoskeletal/opensim/run{run}.nc", run=range(1, 16)),
        code=code_files("scripts.opensim_merge"),
    output:
        "results/musculoskeletal/moments_opensim.nc",
    log:
        "logs/opensim/opensim_merge.log",
    benchmark:
        "results/benchmarks/rules/opensim_merge.tsv"
    conda:
        "../envs/project.yaml"
    params:
        config_slice=cfg("opensim", "scaling", "anthropometry", "design"),
    script:
        "../workflow/scripts/opensim_merge.py"


rule opensim_validate:
    input:
        moments="results/musculoskeletal/moments_opensim.nc",
        ccd="results/doe/ccd.nc",
        code=code_files("scripts.opensim_validate"),
    output:
        nc="results/validation/musculoskeletal.nc",
        plot=report(
            "results/validation/musculoskeletal.png",
            caption="../report/opensim_validation.rst",
            category="Musculoskeletal",
        ),
    log:
        "logs/opensim/opensim_validate.log",
    benchmark:
        "results/benchmarks/rules/opensim_validate.tsv"
    conda:
        "../envs/project.yaml"
    params:
        # A param, not an input: the export is optional (the rule then writes an empty comparison).
        reference=config["opensim"]["reference_path"],
        config_slice=cfg("opensim"),
    script:
        "../workflow/scripts/opensim_validate.py"

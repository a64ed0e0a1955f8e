# Stage authors' settings (beyond the paper): a patient's plans checked by the 2D FEA with the settings of the
# authors' published 2D generator switched on one at a time, then all together. Not in the default run:
#   snakemake -c2 authors_study
# Each variant's config is the base config with its overrides (config authors_study.settings; workflow/authors_study/
# settings.py). The variant's jobs are the default run's rules (sweep, surrogate, plan, FEA check) on that config,
# under results/authors_study/{variant}/; the variants that change the unit run the 2D sweep and surrogate again.
# Input functions live in rules/common.smk (authors_*). Entry point of the table: workflow/authors_study/entry.py.


wildcard_constraints:
    variant="|".join(AUTHORS_VARIANTS),


use rule sweep_shard as authors_sweep_shard with:
    input:
        unpack(get_fem_choice),
        code=code_files("scripts.sweep_shard"),
    output:
        "results/authors_study/{variant}/sweep/{fea}/shard{shard}.nc",
    log:
        "logs/authors_study/sweep_shard/{variant}_{fea}_{shard}.log",
    benchmark:
        "results/benchmarks/rules/authors_sweep_shard_{variant}_{fea}_{shard}.tsv"
    wildcard_constraints:
        fea="2d",
        shard=r"\d+",
        variant="|".join(AUTHORS_UNIT_VARIANTS) or "NONE",
    params:
        sweep=authors_section("sweep", "2d"),
        actuator=authors_section("actuator"),
        config_slice=get_authors_slice("sweep"),


use rule sweep_merge as authors_sweep_merge with:
    input:
        shards=get_authors_sweep_shards,
        code=code_files("scripts.sweep_merge"),
    output:
        "results/authors_study/{variant}/response_{fea}.nc",
    log:
        "logs/authors_study/sweep_merge/{variant}_{fea}.log",
    benchmark:
        "results/benchmarks/rules/authors_sweep_merge_{variant}_{fea}.tsv"
    wildcard_constraints:
        fea="2d",
        variant="|".join(AUTHORS_UNIT_VARIANTS) or "NONE",
    params:
        sweep=authors_section("sweep", "2d"),
        config_slice=get_authors_slice("sweep"),


# the default run's regressor choice (surrogate_cv) is kept: the study changes the unit, not the method; the sweeps
# take the FE study's mesh as the default run's do (fidelity.auto)
use rule surrogate_fit as authors_surrogate_fit with:
    input:
        response="results/authors_study/{variant}/response_{fea}.nc",
        cv="results/actuator/surrogate_cv.nc",
        code=code_files("scripts.surrogate_fit"),
    output:
        model="results/authors_study/{variant}/surrogate_{fea}.joblib",
        plot="results/authors_study/{variant}/response_{fea}.png",
    log:
        "logs/authors_study/surrogate_fit/{variant}_{fea}.log",
    benchmark:
        "results/benchmarks/rules/authors_surrogate_fit_{variant}_{fea}.tsv"
    wildcard_constraints:
        fea="2d",
        variant="|".join(AUTHORS_UNIT_VARIANTS) or "NONE",


# the plan stands on the default run's 3D unit (Table 6, Smooth-Sil 950), as every plan of the paper does, and on the
# chain the default plans use (calibrated when cascade.calibration.use)
use rule cascade_plan as authors_plan with:
    input:
        unpack(get_chain_calibration),
        unit_response=get_unit_response(),
        response=get_unit_response().replace("surrogate_", "response_").replace(".joblib", ".nc"),
        ccd="results/doe/ccd.nc",
        moments="results/musculoskeletal/moments.nc",
        joint_loads="results/patients/{patient}/joint_loads.nc",
        code=code_files("scripts.cascade_plan"),
    output:
        plan="results/authors_study/{variant}/{patient}/cascade_plan.nc",
        plot="results/authors_study/{variant}/{patient}/cascade_poses.png",
    log:
        "logs/authors_study/plan/{variant}_{patient}.log",
    benchmark:
        "results/benchmarks/rules/authors_plan_{variant}_{patient}.tsv"
    params:
        patient=get_patient,
        cascade=authors_section("cascade"),
        anthropometry=authors_section("anthropometry"),
        unit_model=authors_section("surrogates", "unit_model"),
        pressure_limit=get_authors_pressure_limit,
        config_slice=get_authors_slice("plan"),


# the check's mesh is fea_check.h_actuator_mm (the default run's mesh study is not repeated per variant)
use rule fea_check as authors_check with:
    input:
        unpack(get_authors_surrogates),
        plan="results/authors_study/{variant}/{patient}/cascade_plan.nc",
        ccd="results/doe/ccd.nc",
        moments="results/musculoskeletal/moments.nc",
        joint_loads="results/patients/{patient}/joint_loads.nc",
        code=code_files("scripts.fea_check"),
    output:
        nc="results/authors_study/{variant}/{patient}/fea_check.nc",
        vtu=expand(
            "results/authors_study/{{variant}}/{{patient}}/fea_check_{exercise}.vtu",
            exercise=config["authors_study"]["exercises"] or get_fea_exercises(),
        ),
        plot="results/authors_study/{variant}/{patient}/fea_check.png",
    log:
        "logs/authors_study/check/{variant}_{patient}.log",
    benchmark:
        "results/benchmarks/rules/authors_check_{variant}_{patient}.tsv"
    params:
        patient=get_patient,
        fea_check=lambda wildcards: check_keys(authors_config(wildcards.variant)["fea_check"]),
        actuator=authors_section("actuator"),
        cascade=authors_section("cascade"),
        anthropometry=authors_section("anthropometry"),
        unit_model=authors_section("surrogates", "unit_model"),
        tolerance_deg=config["fidelity"]["tolerance"]["check_deg"],
        config_slice=get_authors_slice("check"),


rule authors_study_table:
    input:
        checks=get_authors_checks(),
        code=code_files("scripts.authors_study"),
    output:
        nc="results/authors_study/study.nc",
        table=report(
            "results/authors_study/study.html",
            caption="../report/authors_study.rst",
            category="Authors' settings",
        ),
        plot=report(
            "results/authors_study/study.png",
            caption="../report/authors_study.rst",
            category="Authors' settings",
        ),
    log:
        "logs/authors_study/table.log",
    benchmark:
        "results/benchmarks/rules/authors_study_table.tsv"
    conda:
        "../envs/project.yaml"
    params:
        variants=AUTHORS_VARIANTS,
        patient=authors_patient(),
        changes=get_authors_changes(),
        config_slice={"authors_study": config["authors_study"]},
    script:
        "../workflow/scripts/authors_study.py"


rule authors_study:
    input:
        "results/authors_study/study.nc",
    localrule: True

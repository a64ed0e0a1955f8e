# Stage cascade: per-patient pressure plans on the reduced-order
# finger-actuator model, and their comparison with the paper's Tables 8 and 10.
# Entry points in workflow/cascade/entry.py.


rule cascade_plan:
    input:
        unpack(get_chain_calibration),
        unpack(get_layout_choice),
        unit_response=get_unit_response(),
        # the sweep behind the surrogate: planned pressures outside its converged samples are flagged
        response=get_unit_response().replace("surrogate_", "response_").replace(".joblib", ".nc"),
        ccd="results/doe/ccd.nc",
        moments="results/musculoskeletal/moments.nc",
        joint_loads="results/patients/{patient}/joint_loads.nc",
        code=code_files("scripts.cascade_plan"),
    output:
        plan="results/patients/{patient}/cascade_plan.nc",
        plot=report(
            "results/patients/{patient}/cascade_poses.png",
            caption="../report/cascade_poses.rst",
            category="Cascade",
            subcategory="{patient}",
        ),
    log:
        "logs/cascade/cascade_plan/{patient}.log",
    benchmark:
        "results/benchmarks/rules/cascade_plan_{patient}.tsv"
    conda:
        "../envs/project.yaml"
    params:
        patient=get_patient,
        cascade=config["cascade"],
        anthropometry=config["anthropometry"],
        unit_model=config["surrogates"]["unit_model"],
        pressure_limit=get_pressure_limit(),
        config_slice=get_cascade_slice,
    script:
        "../workflow/scripts/cascade_plan.py"


rule validate_cascade:
    input:
        unpack(get_validation_plans),
        table08="resources/table08_planned_pressures_3d.csv",
        table10="resources/table10_experimental_pressures_mean_finger.csv",
        table07="resources/table07_unit_targets.csv",
        code=code_files("scripts.cascade_validate"),
    output:
        nc="results/validation/cascade.nc",
        plot=report(
            "results/validation/cascade.png",
            caption="../report/cascade_validation.rst",
            category="Cascade",
        ),
    log:
        "logs/cascade/validate_cascade.log",
    benchmark:
        "results/benchmarks/rules/validate_cascade.tsv"
    conda:
        "../envs/project.yaml"
    params:
        rel_floor_kpa=config["cascade"]["rel_floor_kpa"],
        config_slice=cfg("cascade"),
    script:
        "../workflow/scripts/cascade_validate.py"

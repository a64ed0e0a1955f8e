# Stage actuator (section 3.1): nonlinear FEA of the three-chamber PNA unit, its
# pressure sweeps (sharded, resumable), surrogate cross-validation and fit, the
# 2D-to-3D pressure mapping, and the unit under an external end moment.
# Entry points in workflow/actuator/entry.py and entry_fem.py; the FE engine is workflow/fem.


rule unit_check:
    input:
        unpack(get_fem_choice),
        unpack(get_fem_cases),
        code=code_files("scripts.unit_check"),
    output:
        nc=report("results/actuator/unit_check.nc", caption="../report/unit_check.rst", category="Actuator"),
        vtu="results/actuator/unit_3d_300kpa.vtu",
    log:
        "logs/actuator/unit_check.log",
    benchmark:
        "results/benchmarks/rules/unit_check.tsv"
    conda:
        "../envs/project.yaml"
    params:
        actuator=config["actuator"],
        config_slice=cfg("actuator"),
    script:
        "../workflow/scripts/unit_check.py"


# Unit under an external end moment: FEA
# couples at prescribed end rotations against workflow/actuator/unit_model.py.
rule unit_moment_check:
    input:
        code=code_files("scripts.unit_moment_check"),
    output:
        nc=report(
            "results/actuator/unit_moment_check.nc", caption="../report/unit_moment_check.rst", category="Actuator"
        ),
        plot=report(
            "results/actuator/unit_moment_check.png", caption="../report/unit_moment_check.rst", category="Actuator"
        ),
    log:
        "logs/actuator/unit_moment_check.log",
    benchmark:
        "results/benchmarks/rules/unit_moment_check.tsv"
    conda:
        "../envs/project.yaml"
    params:
        actuator=config["actuator"],
        unit_model=config["surrogates"]["unit_model"],
        config_slice=cfg("actuator") | {"surrogates": {"unit_model": config["surrogates"]["unit_model"]}},
    script:
        "../workflow/scripts/unit_moment_check.py"


rule unit_stiffness:
    input:
        surrogate_2d="results/actuator/surrogate_2d.joblib",
        code=code_files("scripts.unit_stiffness"),
    output:
        nc=report("results/actuator/unit_stiffness.nc", caption="../report/unit_stiffness.rst", category="Actuator"),
        plot=report("results/actuator/unit_stiffness.png", caption="../report/unit_stiffness.rst", category="Actuator"),
    log:
        "logs/actuator/unit_stiffness.log",
    benchmark:
        "results/benchmarks/rules/unit_stiffness.tsv"
    conda:
        "../envs/project.yaml"
    params:
        actuator=config["actuator"],
        unit_model=config["surrogates"]["unit_model"],
        config_slice=cfg("actuator") | {"surrogates": {"unit_model": config["surrogates"]["unit_model"]}},
    script:
        "../workflow/scripts/unit_stiffness.py"


# The stiffness study alone (outside the default target unless fea_check.unit_stiffness makes the check read it).
rule stiffness_study:
    input:
        "results/actuator/unit_stiffness.nc",
    localrule: True


rule sweep_shard:
    input:
        unpack(get_fem_choice),
        unpack(get_fem_cases),
        code=code_files("scripts.sweep_shard"),
    output:
        "results/actuator/sweep/{fea}/shard{shard}.nc",
    log:
        "logs/surrogates/sweep_shard/{fea}_{shard}.log",
    benchmark:
        "results/benchmarks/rules/sweep_shard_{fea}_{shard}.tsv"
    wildcard_constraints:
        fea="2d|3d",
        shard=r"\d+",
    priority: sweep_shard_priority  # the plans wait for the sweeps (workflow/common/scheduling.py)
    conda:
        "../envs/project.yaml"
    params:
        sweep=get_sweep_params,
        actuator=config.get("actuator", {}),
        config_slice=get_sweep_slice,
    script:
        "../workflow/scripts/sweep_shard.py"


rule sweep_merge:
    input:
        shards=get_sweep_shards,
        code=code_files("scripts.sweep_merge"),
    output:
        "results/actuator/response_{fea}.nc",
    log:
        "logs/surrogates/sweep_merge/{fea}.log",
    benchmark:
        "results/benchmarks/rules/sweep_merge_{fea}.tsv"
    wildcard_constraints:
        fea="2d|3d",
    conda:
        "../envs/project.yaml"
    params:
        sweep=get_sweep_params,
        config_slice=get_sweep_slice,
    script:
        "../workflow/scripts/sweep_merge.py"


rule surrogate_cv:
    input:
        response_2d="results/actuator/response_2d.nc",
        response_3d="results/actuator/response_3d.nc",
        code=code_files("scripts.surrogate_cv"),
    output:
        cv="results/actuator/surrogate_cv.nc",
        plot=report("results/actuator/surrogate_cv.png", caption="../report/surrogate_cv.rst", category="Actuator"),
    log:
        "logs/surrogates/surrogate_cv.log",
    benchmark:
        "results/benchmarks/rules/surrogate_cv.tsv"
    conda:
        "../envs/project.yaml"
    params:
        surrogates=config["surrogates"],
        # fidelity.auto: the fastest regressor within the tolerance (else the best CV score)
        tolerance=config["fidelity"]["tolerance"]["surrogate_score"] if config["fidelity"]["auto"] else None,
        config_slice=cfg("sweep", "surrogates")
        | {"auto": config["fidelity"]["auto"], "tolerance": config["fidelity"]["tolerance"]["surrogate_score"]},
    script:
        "../workflow/scripts/surrogate_cv.py"


rule surrogate_fit:
    input:
        response="results/actuator/response_{fea}.nc",
        cv="results/actuator/surrogate_cv.nc",
        code=code_files("scripts.surrogate_fit"),
    output:
        model="results/actuator/surrogate_{fea}.joblib",
        plot=report(
            "results/actuator/response_{fea}.png",
            caption="../report/surrogate_response.rst",
            category="Actuator",
        ),
    log:
        "logs/surrogates/surrogate_fit/{fea}.log",
    benchmark:
        "results/benchmarks/rules/surrogate_fit_{fea}.tsv"
    wildcard_constraints:
        fea="2d|3d",
    conda:
        "../envs/project.yaml"
    params:
        surrogates=config["surrogates"],
    script:
        "../workflow/scripts/surrogate_fit.py"


rule mapping_2d3d:
    input:
        table="resources/table08_planned_pressures_3d.csv",
        table07="resources/table07_unit_targets.csv",
        surrogate_3d="results/actuator/surrogate_3d.joblib",
        surrogate_2d="results/actuator/surrogate_2d.joblib",
        code=code_files("scripts.mapping_2d3d"),
    output:
        nc="results/actuator/mapping_2d3d.nc",
        plot=report(
            "results/actuator/mapping_2d3d.png",
            caption="../report/surrogate_mapping.rst",
            category="Actuator",
        ),
    log:
        "logs/surrogates/mapping_2d3d.log",
    benchmark:
        "results/benchmarks/rules/mapping_2d3d.tsv"
    conda:
        "../envs/project.yaml"
    params:
        pressure_limit=get_pressure_limit(),
        unit_model=config["surrogates"]["unit_model"],
        config_slice=get_mapping_slice(),
    script:
        "../workflow/scripts/mapping_2d3d.py"

# Stage surrogates: pressure sweeps of the FE unit models (sharded,
# resumable), surrogate cross-validation and fit, 2D-to-3D pressure mapping.
# Science in workflow/sweep.py, surrogates.py, mapping.py, plots_actuator.py.


rule sweep_shard:
    input:
        unpack(get_fem_choice),
        code=code_files("sweep", "fem", "fidelity"),
    output:
        "results/actuator/sweep/{fea}/shard{shard}.nc",
    wildcard_constraints:
        fea="2d|3d",
        shard=r"\d+",
    params:
        sweep=get_sweep_params,
        actuator=config.get("actuator", {}),
        config_slice=get_sweep_slice,
    log:
        "logs/surrogates/sweep_shard/{fea}_{shard}.log",
    benchmark:
        "results/benchmarks/rules/sweep_shard_{fea}_{shard}.tsv"
    script:
        "../workflow/scripts/sweep_shard.py"


rule sweep_merge:
    input:
        shards=get_sweep_shards,
        code=code_files("sweep"),
    output:
        "results/actuator/response_{fea}.nc",
    wildcard_constraints:
        fea="2d|3d",
    params:
        sweep=get_sweep_params,
        config_slice=get_sweep_slice,
    log:
        "logs/surrogates/sweep_merge/{fea}.log",
    benchmark:
        "results/benchmarks/rules/sweep_merge_{fea}.tsv"
    script:
        "../workflow/scripts/sweep_merge.py"


rule surrogate_cv:
    input:
        response_2d="results/actuator/response_2d.nc",
        response_3d="results/actuator/response_3d.nc",
        code=code_files("surrogates", "plots_actuator"),
    output:
        cv="results/actuator/surrogate_cv.nc",
        plot=report("results/actuator/surrogate_cv.png", caption="../report/surrogate_cv.rst", category="Actuator"),
    params:
        surrogates=config["surrogates"],
        # fidelity.auto: the fastest regressor within the tolerance (else the best CV score)
        tolerance=config["fidelity"]["tolerance"]["surrogate_score"] if config["fidelity"]["auto"] else None,
        config_slice=cfg("sweep", "surrogates") | {"auto": config["fidelity"]["auto"],
                                                   "tolerance": config["fidelity"]["tolerance"]["surrogate_score"]},
    log:
        "logs/surrogates/surrogate_cv.log",
    benchmark:
        "results/benchmarks/rules/surrogate_cv.tsv"
    script:
        "../workflow/scripts/surrogate_cv.py"


rule surrogate_fit:
    input:
        response="results/actuator/response_{fea}.nc",
        cv="results/actuator/surrogate_cv.nc",
        code=code_files("surrogates", "plots_actuator"),
    output:
        model="results/actuator/surrogate_{fea}.joblib",
        plot=report(
            "results/actuator/response_{fea}.png",
            caption="../report/surrogate_response.rst",
            category="Actuator",
        ),
    wildcard_constraints:
        fea="2d|3d",
    params:
        surrogates=config["surrogates"],
    log:
        "logs/surrogates/surrogate_fit/{fea}.log",
    benchmark:
        "results/benchmarks/rules/surrogate_fit_{fea}.tsv"
    script:
        "../workflow/scripts/surrogate_fit.py"


rule mapping_2d3d:
    input:
        table="resources/table08_planned_pressures_3d.csv",
        surrogate_3d="results/actuator/surrogate_3d.joblib",
        surrogate_2d="results/actuator/surrogate_2d.joblib",
        code=code_files("mapping", "surrogates", "plots_actuator"),
    output:
        nc="results/actuator/mapping_2d3d.nc",
        plot=report(
            "results/actuator/mapping_2d3d.png",
            caption="../report/surrogate_mapping.rst",
            category="Actuator",
        ),
    params:
        pressure_limit=get_pressure_limit(),
        config_slice=cfg("sweep", "surrogates") | {"pressure_limit": get_pressure_limit()},
    log:
        "logs/surrogates/mapping_2d3d.log",
    benchmark:
        "results/benchmarks/rules/mapping_2d3d.tsv"
    script:
        "../workflow/scripts/mapping_2d3d.py"

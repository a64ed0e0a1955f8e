# Stage doe: the central composite design and the OpenSim scale factors per run.


rule ccd:
    input:
        code=code_files("scripts.ccd"),
    output:
        "results/doe/ccd.nc",
    params:
        design=config["design"],
    log:
        "logs/doe/ccd.log",
    benchmark:
        "results/benchmarks/rules/ccd.tsv"
    script:
        "../workflow/scripts/ccd.py"


rule scaling:
    input:
        ccd="results/doe/ccd.nc",
        code=code_files("scripts.scaling"),
    output:
        "results/doe/scaling.nc",
    params:
        scaling=config["scaling"],
        anthropometry=config["anthropometry"],
    log:
        "logs/doe/scaling.log",
    benchmark:
        "results/benchmarks/rules/scaling.tsv"
    script:
        "../workflow/scripts/scaling.py"


rule validate_scaling:
    input:
        scaling="results/doe/scaling.nc",
        table="resources/table03_04_ccd_scaling.csv",
        code=code_files("scripts.validate_scaling"),
    output:
        report("results/validation/scaling.nc", caption="../report/scaling.rst", category="Musculoskeletal"),
    log:
        "logs/validation/scaling.log",
    benchmark:
        "results/benchmarks/rules/validate_scaling.tsv"
    script:
        "../workflow/scripts/validate_scaling.py"

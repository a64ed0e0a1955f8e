# Stage doe: the central composite design and the OpenSim scale factors per run.


rule ccd:
    input:
        code=code_files("scripts.ccd"),
    output:
        "results/doe/ccd.nc",
    log:
        "logs/doe/ccd.log",
    benchmark:
        "results/benchmarks/rules/ccd.tsv"
    conda:
        "../envs/project.yaml"
    params:
        design=config["design"],
    script:
        "../workflow/scripts/ccd.py"


rule scaling:
    input:
        ccd="results/doe/ccd.nc",
        code=code_files("scripts.scaling"),
    output:
        "results/doe/scaling.nc",
    log:
        "logs/doe/scaling.log",
    benchmark:
        "results/benchmarks/rules/scaling.tsv"
    conda:
        "../envs/project.yaml"
    params:
        scaling=config["scaling"],
        anthropometry=config["anthropometry"],
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
    conda:
        "../envs/project.yaml"
    script:
        "../workflow/scripts/validate_scaling.py"

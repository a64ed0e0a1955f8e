# Stage actuator (issue 4): nonlinear FEA of the three-chamber PNA unit.
# Science in workflow/fem (scikit-fem).


rule unit_check:
    input:
        code=code_files("fem"),
    output:
        nc=report("results/actuator/unit_check.nc", caption="../report/unit_check.rst", category="Actuator"),
        vtu="results/actuator/unit_3d_300kpa.vtu",
    params:
        actuator=config["actuator"],
        config_slice=cfg("actuator"),
    log:
        "logs/actuator/unit_check.log",
    benchmark:
        "results/benchmarks/rules/unit_check.tsv"
    script:
        "../workflow/scripts/unit_check.py"

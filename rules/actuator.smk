# Stage actuator: nonlinear FEA of the three-chamber PNA unit.
# Science in workflow/fem (scikit-fem).


rule unit_check:
    input:
        unpack(get_fem_choice),
        code=code_files("fem", "fidelity"),
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


# Unit under an external end moment: FEA
# couples at prescribed end rotations against workflow/unit_model.py.
rule unit_moment_check:
    input:
        code=code_files("fem", "unit_moment_check", "unit_model"),
    output:
        nc=report("results/actuator/unit_moment_check.nc", caption="../report/unit_moment_check.rst", category="Actuator"),
        plot=report("results/actuator/unit_moment_check.png", caption="../report/unit_moment_check.rst", category="Actuator"),
    params:
        actuator=config["actuator"],
        unit_model=config["surrogates"]["unit_model"],
        config_slice={"actuator": config["actuator"], "surrogates": {"unit_model": config["surrogates"]["unit_model"]}},
    log:
        "logs/actuator/unit_moment_check.log",
    benchmark:
        "results/benchmarks/rules/unit_moment_check.tsv"
    script:
        "../workflow/scripts/unit_moment_check.py"

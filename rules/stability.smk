# Stage stability: where each method fails or degrades. Two
# small FE studies of the 2D unit (extra rays by mesh, contact and formulation;
# locking against K/mu0) and the maps built from the sweeps, the unit check,
# the surrogates' sampled region, the patients' coded levels and their plans.
# Entry points in workflow/stability/entry.py, figures in workflow/stability/plots.py.


rule stability_rays:
    input:
        code=code_files("scripts.stability_rays"),
    output:
        "results/stability/rays_2d.nc",
    log:
        "logs/stability/stability_rays.log",
    benchmark:
        "results/benchmarks/rules/stability_rays.tsv"
    conda:
        "../envs/project.yaml"
    params:
        rays=config["stability"]["rays"],
        # only the parts of the unit model the rays use (not its sweep or check settings)
        actuator=get_actuator_part("geometry", "material", "mesh", "contact", "solver"),
        config_slice=get_stability_slice("rays", "geometry", "material", "mesh", "contact", "solver"),
    script:
        "../workflow/scripts/stability_rays.py"


rule stability_locking:
    input:
        code=code_files("scripts.stability_locking"),
    output:
        "results/stability/locking.nc",
    log:
        "logs/stability/stability_locking.log",
    benchmark:
        "results/benchmarks/rules/stability_locking.tsv"
    conda:
        "../envs/project.yaml"
    params:
        locking=config["stability"]["locking"],
        actuator=get_actuator_part("geometry", "material", "solver"),
        config_slice=get_stability_slice("locking", "geometry", "material", "solver"),
    script:
        "../workflow/scripts/stability_locking.py"


rule stability_maps:
    input:
        response_2d="results/actuator/response_2d.nc",
        response_3d="results/actuator/response_3d.nc",
        unit_check="results/actuator/unit_check.nc",
        rays="results/stability/rays_2d.nc",
        locking="results/stability/locking.nc",
        ccd="results/doe/ccd.nc",
        loads=expand("results/patients/{patient}/joint_loads.nc", patient=PATIENTS),
        plans=expand("results/patients/{patient}/cascade_plan.nc", patient=PATIENTS),
        fem_cases=expand("results/fidelity/fem/{case}.nc", case=FEM_CASES),
        code=code_files("scripts.stability_maps"),
    output:
        nc="results/stability/stability.nc",
        failures=report(
            "results/stability/newton_failures.png",
            caption="../report/stability_failures.rst",
            category="Stability maps",
        ),
        locking=report(
            "results/stability/locking.png", caption="../report/stability_locking.rst", category="Stability maps"
        ),
        penetration=report(
            "results/stability/penetration.png",
            caption="../report/stability_penetration.rst",
            category="Stability maps",
        ),
        coverage=report(
            "results/stability/surrogate_coverage.png",
            caption="../report/stability_coverage.rst",
            category="Stability maps",
        ),
        design=report(
            "results/stability/design_feasibility.png",
            caption="../report/stability_design.rst",
            category="Stability maps",
        ),
        table=report(
            "results/stability/summary.html", caption="../report/stability_summary.rst", category="Stability maps"
        ),
    log:
        "logs/stability/stability_maps.log",
    benchmark:
        "results/benchmarks/rules/stability_maps.tsv"
    conda:
        "../envs/project.yaml"
    params:
        patients=PATIENTS,
        # the sweeps' and unit check's element sizes and contact switch (labels of the maps)
        actuator=get_actuator_part("mesh", "contact"),
        stability=config["stability"],
        cascade_surrogate=config["cascade"]["surrogate"],
        config_slice=get_maps_slice(),
    script:
        "../workflow/scripts/stability_maps.py"

# Stage layout design (beyond the paper): the units per group that make the most exercises reachable at the least
# pressure. Every layout within config layout.bounds is planned on the reduced-order chain (calibrated to the FEA
# by rule chain_calibration when layout.calibrated), the best layout.confirm_top are planned again and checked by the
# 2D FEA (the default run's rules on that layout), beside the default layout (layout.check_default: the plan's units
# without this stage), and the one the FEA finds best is chosen. Not in the default run:
#   snakemake -c2 design_layouts        (the patients of layout.patients)
#   snakemake -c2 layout_<patient>
# With layout.use, a designed patient's plan uses its chosen layout. Entry points: workflow/layout/entry.py (search),
# workflow/layout/entry_choice.py (choice).


rule layout_search:
    input:
        unpack(get_layout_calibration),
        unit_response=get_unit_response(),
        ccd="results/doe/ccd.nc",
        moments="results/musculoskeletal/moments.nc",
        joint_loads="results/patients/{patient}/joint_loads.nc",
        code=code_files("scripts.layout_search"),
    output:
        nc="results/patients/{patient}/layout/search.nc",
    log:
        "logs/layout/layout_search/{patient}.log",
    benchmark:
        "results/benchmarks/rules/layout_search_{patient}.tsv"
    conda:
        "../envs/project.yaml"
    params:
        patient=get_patient,
        cascade=cascade_cfg_without(),
        anthropometry=config["anthropometry"],
        unit_model=config["surrogates"]["unit_model"],
        layout=layout_search_cfg(),
        pressure_limit=get_pressure_limit(),
        config_slice=get_layout_slice,
    script:
        "../workflow/scripts/layout_search.py"


# the plan of the chain's rank-k layout: the default plan rule on the chain the search ranked on, its units per group
# read from the search
use rule cascade_plan as layout_plan with:
    input:
        unpack(layout_plan_inputs(ranked=True)),
    output:
        plan="results/patients/{patient}/layout/top{rank}/cascade_plan.nc",
        plot="results/patients/{patient}/layout/top{rank}/cascade_poses.png",
    log:
        "logs/layout/layout_plan/{patient}_{rank}.log",
    benchmark:
        "results/benchmarks/rules/layout_plan_{patient}_{rank}.tsv"
    wildcard_constraints:
        rank=r"\d+",
    params:
        patient=get_patient,
        cascade=cascade_cfg_without(),
        anthropometry=config["anthropometry"],
        unit_model=config["surrogates"]["unit_model"],
        pressure_limit=get_pressure_limit(),
        layout_rank=get_layout_rank,
        config_slice=get_layout_plan_slice,


# the check's mesh is fea_check.h_actuator_mm: the mesh study checks the validation patient's plan, which with
# layout.use depends on this check
use rule fea_check as layout_check with:
    input:
        unpack(get_fea_surrogates),
        plan="results/patients/{patient}/layout/top{rank}/cascade_plan.nc",
        ccd="results/doe/ccd.nc",
        moments="results/musculoskeletal/moments.nc",
        joint_loads="results/patients/{patient}/joint_loads.nc",
        code=code_files("scripts.fea_check"),
    output:
        nc="results/patients/{patient}/layout/top{rank}/fea_check.nc",
        vtu=expand(
            "results/patients/{{patient}}/layout/top{{rank}}/fea_check_{exercise}.vtu", exercise=get_fea_exercises()
        ),
        plot="results/patients/{patient}/layout/top{rank}/fea_check.png",
    log:
        "logs/layout/layout_check/{patient}_{rank}.log",
    benchmark:
        "results/benchmarks/rules/layout_check_{patient}_{rank}.tsv"
    wildcard_constraints:
        rank=r"\d+",


# the default layout (cascade.units_per_group, else the length rule: the plan a patient gets without the layout design) planned on the chain the search ranked
# on and checked on the same mesh, so the choice can keep it when the FEA finds the chain's best no better
use rule layout_plan as layout_default_plan with:
    input:
        unpack(layout_plan_inputs(ranked=False)),
    output:
        plan="results/patients/{patient}/layout/default/cascade_plan.nc",
        plot="results/patients/{patient}/layout/default/cascade_poses.png",
    log:
        "logs/layout/layout_plan/{patient}_default.log",
    benchmark:
        "results/benchmarks/rules/layout_plan_{patient}_default.tsv"


use rule layout_check as layout_default_check with:
    input:
        unpack(get_fea_surrogates),
        plan="results/patients/{patient}/layout/default/cascade_plan.nc",
        ccd="results/doe/ccd.nc",
        moments="results/musculoskeletal/moments.nc",
        joint_loads="results/patients/{patient}/joint_loads.nc",
        code=code_files("scripts.fea_check"),
    output:
        nc="results/patients/{patient}/layout/default/fea_check.nc",
        vtu=expand("results/patients/{{patient}}/layout/default/fea_check_{exercise}.vtu", exercise=get_fea_exercises()),
        plot="results/patients/{patient}/layout/default/fea_check.png",
    log:
        "logs/layout/layout_check/{patient}_default.log",
    benchmark:
        "results/benchmarks/rules/layout_check_{patient}_default.tsv"


rule layout_choice:
    input:
        unpack(get_layout_checks),
        search="results/patients/{patient}/layout/search.nc",
        code=code_files("scripts.layout_choice"),
    output:
        nc="results/patients/{patient}/layout.nc",
        plot=report(
            "results/patients/{patient}/layout.png",
            caption="../report/layout.rst",
            category="Layout design",
            subcategory="{patient}",
        ),
    log:
        "logs/layout/layout_choice/{patient}.log",
    benchmark:
        "results/benchmarks/rules/layout_choice_{patient}.tsv"
    conda:
        "../envs/project.yaml"
    params:
        config_slice=lambda wildcards: {k: config["layout"][k] for k in ("confirm_top", "check_default")},
    script:
        "../workflow/scripts/layout_choice.py"


rule design_layouts:
    input:
        expand("results/patients/{patient}/layout.nc", patient=config["layout"]["patients"]),
    localrule: True


for _patient in PATIENTS:

    rule:
        name:
            f"layout_{_patient}"
        input:
            f"results/patients/{_patient}/layout.nc",
        localrule: True

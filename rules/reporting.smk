# Stage report: what `snakemake --report report.html` shows
# beyond the stages' own plots -- the moment-angle curves and the tables (one
# small HTML page each, shown inline). Science-free: workflow/reporting/ and
# workflow/musculoskeletal/plots.py only reformat datasets.


rule moment_angle_plot:
    input:
        moments="results/musculoskeletal/moments.nc",
        code=code_files("scripts.moment_angle_plot"),
    output:
        report(
            "results/musculoskeletal/moment_angle.png",
            caption="../report/moment_angle.rst",
            category="Musculoskeletal",
        ),
    log:
        "logs/report/moment_angle_plot.log",
    benchmark:
        "results/benchmarks/rules/moment_angle_plot.tsv"
    conda:
        "../envs/project.yaml"
    script:
        "../workflow/scripts/moment_angle_plot.py"


rule report_table:
    input:
        dataset=get_report_dataset,
        code=code_files("scripts.report_table"),
    output:
        report("results/report/{table}.html", caption="../report/tables.rst", category="Tables"),
    log:
        "logs/report/report_table_{table}.log",
    benchmark:
        "results/benchmarks/rules/report_table_{table}.tsv"
    wildcard_constraints:
        table="|".join(REPORT_DATASETS),
    conda:
        "../envs/project.yaml"
    script:
        "../workflow/scripts/report_table.py"


rule joint_loads_table:
    input:
        dataset="results/patients/{patient}/joint_loads.nc",
        code=code_files("scripts.report_table"),
    output:
        report(
            "results/patients/{patient}/joint_loads.html",
            caption="../report/tables.rst",
            category="Patients",
            subcategory="{patient}",
        ),
    log:
        "logs/report/joint_loads_table_{patient}.log",
    benchmark:
        "results/benchmarks/rules/joint_loads_table_{patient}.tsv"
    conda:
        "../envs/project.yaml"
    params:
        table="joint_loads",
    script:
        "../workflow/scripts/report_table.py"


rule cascade_plan_table:
    input:
        dataset="results/patients/{patient}/cascade_plan.nc",
        code=code_files("scripts.report_table"),
    output:
        report(
            "results/patients/{patient}/cascade_plan.html",
            caption="../report/tables.rst",
            category="Cascade",
            subcategory="{patient}",
        ),
    log:
        "logs/report/cascade_plan_table_{patient}.log",
    benchmark:
        "results/benchmarks/rules/cascade_plan_table_{patient}.tsv"
    conda:
        "../envs/project.yaml"
    params:
        table="cascade_plan",
    script:
        "../workflow/scripts/report_table.py"

# Stage opensim: the generated OpenSim finger model, scaled per CCD run
# with OpenSim's own scaling and sampled into moment-angle curves; the merged file
# becomes results/musculoskeletal/moments.nc when musculoskeletal.backend = opensim.


rule opensim_model:
    input:
        parameters=config["opensim"]["parameters"],
        scaling="results/doe/scaling.nc",
        code=code_files("musculoskeletal.opensim_model", "musculoskeletal.opensim_backend"),
    output:
        "results/musculoskeletal/opensim/finger_reference.osim",
    params:
        fingers=config["opensim"]["fingers"],
        reference_marker=config["opensim"]["reference_marker"],
    log:
        "logs/opensim/opensim_model.log",
    benchmark:
        "results/benchmarks/rules/opensim_model.tsv"
    script:
        "../workflow/scripts/opensim_model.py"


rule opensim_sample:
    input:
        model="results/musculoskeletal/opensim/finger_reference.osim",
        scaling="results/doe/scaling.nc",
        code=code_files("musculoskeletal.opensim_model", "musculoskeletal.opensim_backend"),
    output:
        "results/musculoskeletal/opensim/run{run}.nc",
    params:
        fingers=config["opensim"]["fingers"],
        angle_step_deg=config["opensim"]["angle_step_deg"],
        activations=config["opensim"]["activations"],
        include_gravity=config["opensim"]["include_gravity"],
        config_slice=cfg("opensim", "scaling", "anthropometry", "design"),
    wildcard_constraints:
        run=r"\d+",
    log:
        "logs/opensim/opensim_sample_{run}.log",
    benchmark:
        "results/benchmarks/rules/opensim_sample_{run}.tsv"
    script:
        "../workflow/scripts/opensim_sample.py"


rule opensim_merge:
    input:
        # A three-factor CCD has 15 runs (2^3 corners, 6 axial points, the centre).
        runs=expand("results/musculoskeletal/opensim/run{run}.nc", run=range(1, 16)),
        code=code_files("musculoskeletal.opensim_backend"),
    output:
        "results/musculoskeletal/moments_opensim.nc",
    params:
        config_slice=cfg("opensim", "scaling", "anthropometry", "design"),
    log:
        "logs/opensim/opensim_merge.log",
    benchmark:
        "results/benchmarks/rules/opensim_merge.tsv"
    script:
        "../workflow/scripts/opensim_merge.py"


rule opensim_validate:
    input:
        moments="results/musculoskeletal/moments_opensim.nc",
        ccd="results/doe/ccd.nc",
        code=code_files("musculoskeletal.validation"),
    output:
        nc="results/validation/musculoskeletal.nc",
        plot=report(
            "results/validation/musculoskeletal.png",
            caption="../report/opensim_validation.rst",
            category="Musculoskeletal",
        ),
    params:
        # A param, not an input: the export is optional (the rule then writes an empty comparison).
        reference=config["opensim"]["reference_path"],
        config_slice=cfg("opensim"),
    log:
        "logs/opensim/opensim_validate.log",
    benchmark:
        "results/benchmarks/rules/opensim_validate.tsv"
    script:
        "../workflow/scripts/opensim_validate.py"

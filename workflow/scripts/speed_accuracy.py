from workflow.fidelity.entry import write_speed_accuracy
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
p, i = snakemake.params, snakemake.input  # noqa: F821
plan_inputs = None
if "joint_loads" in i.keys():
    plan_inputs = {
        "patient": p.patient,
        "joint_loads": i.joint_loads,
        "moments": i.moments_all,
        "ccd": i.ccd,
        "cascade": p.cascade,
        "anthropometry": p.anthropometry,
        "unit_model": p.unit_model,
    }
write_speed_accuracy(
    snakemake.output.nc,
    snakemake.output.plot,
    fem_nc=i.fem,  # noqa: F821
    responses={"2d": i.response_2d, "3d": i.response_3d},
    cv_nc=i.cv,
    msk_nc=i.msk,
    check_nc=i.get("check"),
    plan_inputs=plan_inputs,
    surrogates_cfg=p.surrogates,
    config_slice=p.config_slice,
    rule=snakemake.rule,
)  # noqa: F821

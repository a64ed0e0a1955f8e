from workflow.fea_check import write_fea_check
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
p = snakemake.params  # noqa: F821
i = snakemake.input  # noqa: F821
o = snakemake.output  # noqa: F821
write_fea_check(snakemake.wildcards.patient, p.patient, plan_nc=i.plan, joint_loads_nc=i.joint_loads,  # noqa: F821
                moments_nc=i.moments, ccd_nc=i.ccd, out_nc=o.nc, out_vtu=list(o.vtu), out_png=o.plot,
                fea_cfg=p.fea_check, actuator_cfg=p.actuator, cascade_cfg=p.cascade, anthropometry=p.anthropometry,
                config_slice=p.config_slice, surrogate_2d=i.get("surrogate_2d"), surrogate_3d=i.get("surrogate_3d"),
                unit_model_cfg=p.unit_model, rule=snakemake.rule)  # noqa: F821

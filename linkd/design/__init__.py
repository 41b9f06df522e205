"""`linkd design`: from a target curve to a verified, exported mechanism that traces it.

One module per stage, data flowing one way: `propose` (LinkD samples for the curve and its
turned and mirrored copies, placed on the curve by similarity alignment), `refine` (batched
L-BFGS through the differentiable kinematics, `lbfgs`), `select` (topologies, curve error,
design figures), `output` (export, MuJoCo verification, plots, report) and `pipeline` (the
staged, timed run that writes the output folder); `bench` measures it on folders of curves.
"""

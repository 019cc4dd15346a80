"""Parametric baselines that the discovered models are compared against.

- GA with a gradient operator on the 12-state model (ga-gradient-parameter-identification):
  `symbolic` (model, cost, analytic gradient), `quad12` (model and simulator), `ga` (the
  real-valued GA), `ga_identify` (per-loop identification and the convergence study).
- Prediction-error method on the body-centric model (body-centric-pem-lq-tracker):
  `body_kernels` (closed/open-loop rollout), `geometry` (analytic initial guesses),
  `pem_sim` (closed-loop truth simulator), `pem` (cost eq. 17 and the optimiser).
- `schema` (strict TOML configs), `runfolder` (model.json/run.json, loading),
  `cli` (`gpquad baseline ...`, `gpquad compare ...`).
"""

"""The paper's tables and figures and our studies, each a script (`python -m
experiments.paper.NAME`); they write files only, so matplotlib draws on its Agg backend."""

import matplotlib

matplotlib.use("Agg")

"""The papers' reproductions, on top of the library: what the CLI and the example scripts run.

- :mod:`~sahgrasp.experiments.arguments`: the command-line options shared by the commands and the
  examples (no heavy import: parsers are built for ``--help``), and the default chart radius and
  epsilon of each atlas experiment;
- :mod:`~sahgrasp.experiments.reference`: what the atlas paper reports, to print ours beside it;
- :mod:`~sahgrasp.experiments.setups`: the atlas paper's experiments (the planar hand, the SAH with
  the can or the oil bottle) as grasp manifolds, and running them;
- :mod:`~sahgrasp.experiments.report`: their JSON summaries and text reports;
- :mod:`~sahgrasp.experiments.plotting`: their matplotlib figures (matplotlib imported on use);
- :mod:`~sahgrasp.experiments.ik_examples` and :mod:`~sahgrasp.experiments.atlas_examples`: the
  example scripts' mains (solve or optimise, report beside the paper, show);
- :mod:`~sahgrasp.experiments.doc_tables`: the docs' number tables, regenerated from the code.

No library module (hand, contacts, ik, sequence, atlas, quality, grasp, planar, optimization,
objects, viz) imports this package.
"""

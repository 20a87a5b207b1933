"""trackenv_agents: the agents of trackenv, by job (the folder ``agents``).

* :mod:`trackenv_agents.rules` — the heuristic maintenance rules and their tuned parameters per preset;
* :mod:`trackenv_agents.learning` — the learners: PPO on the 60 m track (Tamping-v1), the per-section line policy
  and its counterfactual training, imitation, the SB3 vector envs, hyper-parameters and the shipped models;
* :mod:`trackenv_agents.evaluation` — the evaluation harness, its statistics, tuning, comparisons, reports, the
  hindsight bound and the distributed executor;
* :mod:`trackenv_agents.cli` — the ``trackenv`` command.

Each subpackage re-exports the public names of its modules. The library ``trackenv`` never imports this package.
"""

"""What every algorithm's training shares: the configuration, the seed rules, the spaces crowdnav builds, the algorithm
seam (:mod:`crowdnav.agents.training.algorithm_protocol`), the env wrappers, the checks around a run, the one run loop
every run goes through (:mod:`crowdnav.agents.training.run_loop`), crowdnav's episode loop for algorithms outside SB3,
and ``train(config)`` itself (:mod:`crowdnav.agents.training.run`)."""

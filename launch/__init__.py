"""The commands: the swarm, the experiments, the fault schedules, the router and the secured setup."""

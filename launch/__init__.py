"""The commands: the swarm, the experiments, the fault schedules, the router and the secured
setup; and what every command shares at the terminal (``cli``)."""

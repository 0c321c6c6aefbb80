"""Studies: the paper's 2-D study (Sec. V) and robot study (Sec. VI) in simulation, and sweeps over seeds."""

"""Learning from demonstrations: the privileged social-force robot's episodes collected as transitions, and behaviour
cloning of an SB3 model on them (the warm start before, and under, RL)."""

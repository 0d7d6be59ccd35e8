"""The networks of the shared multi-modal latent: one branch per observation key (LEOG CNN, LIDAR, RBF and
low-dimensional layers), the extractor that concatenates them, their parameter counts before allocation, and the
LEOG encoder's pre-training as an autoencoder on collected occupancy grids."""

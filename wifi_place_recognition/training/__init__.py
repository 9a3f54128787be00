"""Training with torch: the network, selection on held-out groups, the trainer."""

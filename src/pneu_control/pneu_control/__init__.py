"""pneu_control: controller cores, experiments, analysis, the pneu CLI and the controller/logger nodes."""

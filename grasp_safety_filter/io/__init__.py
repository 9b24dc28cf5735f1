"""Input and output: parameters and config files, topics, messages, bags, paths."""

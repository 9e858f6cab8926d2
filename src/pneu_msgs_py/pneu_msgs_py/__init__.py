"""pneu message contract: topics, QoS, units, conversions, parameters, MCAP."""

__version__ = "0.1.0"

"""The message contract: topics, QoS, units, sensor samples and message conversions."""

"""The driver's 1 kHz read -> check -> publish -> command -> write loop and its real-time setup."""

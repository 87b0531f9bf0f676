"""The application: config, control law, motion, simulated world, session, recording, CLI."""

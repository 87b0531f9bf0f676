"""Everything that stands in for the world: renderer, specimens, simulated world, bridge emulator."""

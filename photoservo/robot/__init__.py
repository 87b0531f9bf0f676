"""The arm: PA-10 kinematics, wire protocol, serial link and controller emulator."""

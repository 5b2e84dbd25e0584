"""Rendezvous motion: the chaser's relative orbit (Hill-Clohessy-Wiltshire), the target's attitude along
it (held, inertial, spin, torque-free tumble), and the sequences of frames they give (`[sequence]`)."""

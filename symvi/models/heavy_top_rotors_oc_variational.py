"""The heavy top with two rotors (:mod:`.heavy_top_rotors_oc`) with its controlled
equations discretised variationally: the forced discrete Euler–Lagrange equations of the
first-order L_d, whose exact discrete vertical-momentum identity the solver uses to fix the
multipliers (:mod:`symvi.declaration.control`)."""
from .heavy_top_rotors_oc import build

model = build(equations="variational")

"""Time stepping of one SD realisation: shear protocol, forces, Brownian terms, media."""

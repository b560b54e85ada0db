"""Reference numbers from the UniTac-NV paper (Hou et al., IROS 2025), carried here so reports can show them beside
ours. Table I: normalised MAE / SSIM on the test set; Section IV: contact-geometry errors in mm.
"""

from __future__ import annotations

# Table I columns, in the paper's order: individually trained autoencoders, then UniTac-NV directions.
TABLE1_COLUMNS: tuple[str, ...] = (
    "ae_uskin",
    "ae_papillarray",
    "uskin_to_uskin",
    "uskin_to_papillarray",
    "papillarray_to_papillarray",
    "papillarray_to_uskin",
)

# Table I rows: object ids (material x shape), then the pooled rows.
TABLE1_ROWS: tuple[str, ...] = (
    "circle_pla",
    "square_pla",
    "hex_pla",
    "circle_tpu",
    "square_tpu",
    "hex_tpu",
    "all_seen",
    "irregular_pla",
)

# (NMAE, SSIM) per row and column, as printed in the paper.
PAPER_TABLE1: dict[str, dict[str, tuple[float, float]]] = {
    "circle_pla": {
        "ae_uskin": (0.014, 0.996),
        "ae_papillarray": (0.008, 0.997),
        "uskin_to_uskin": (0.018, 0.984),
        "uskin_to_papillarray": (0.020, 0.992),
        "papillarray_to_papillarray": (0.010, 0.995),
        "papillarray_to_uskin": (0.031, 0.973),
    },
    "square_pla": {
        "ae_uskin": (0.032, 0.981),
        "ae_papillarray": (0.020, 0.993),
        "uskin_to_uskin": (0.038, 0.981),
        "uskin_to_papillarray": (0.044, 0.958),
        "papillarray_to_papillarray": (0.031, 0.973),
        "papillarray_to_uskin": (0.064, 0.957),
    },
    "hex_pla": {
        "ae_uskin": (0.034, 0.965),
        "ae_papillarray": (0.016, 0.996),
        "uskin_to_uskin": (0.041, 0.955),
        "uskin_to_papillarray": (0.031, 0.985),
        "papillarray_to_papillarray": (0.027, 0.990),
        "papillarray_to_uskin": (0.050, 0.944),
    },
    "circle_tpu": {
        "ae_uskin": (0.020, 0.992),
        "ae_papillarray": (0.009, 0.997),
        "uskin_to_uskin": (0.029, 0.983),
        "uskin_to_papillarray": (0.021, 0.991),
        "papillarray_to_papillarray": (0.013, 0.994),
        "papillarray_to_uskin": (0.041, 0.955),
    },
    "square_tpu": {
        "ae_uskin": (0.032, 0.972),
        "ae_papillarray": (0.020, 0.990),
        "uskin_to_uskin": (0.037, 0.962),
        "uskin_to_papillarray": (0.040, 0.950),
        "papillarray_to_papillarray": (0.027, 0.989),
        "papillarray_to_uskin": (0.059, 0.939),
    },
    "hex_tpu": {
        "ae_uskin": (0.030, 0.986),
        "ae_papillarray": (0.018, 0.996),
        "uskin_to_uskin": (0.042, 0.981),
        "uskin_to_papillarray": (0.040, 0.974),
        "papillarray_to_papillarray": (0.030, 0.990),
        "papillarray_to_uskin": (0.066, 0.947),
    },
    "all_seen": {
        "ae_uskin": (0.027, 0.982),
        "ae_papillarray": (0.015, 0.995),
        "uskin_to_uskin": (0.034, 0.974),
        "uskin_to_papillarray": (0.033, 0.975),
        "papillarray_to_papillarray": (0.023, 0.989),
        "papillarray_to_uskin": (0.052, 0.953),
    },
    "irregular_pla": {
        "ae_uskin": (0.111, 0.862),
        "ae_papillarray": (0.036, 0.982),
        "uskin_to_uskin": (0.125, 0.845),
        "uskin_to_papillarray": (0.136, 0.858),
        "papillarray_to_papillarray": (0.058, 0.961),
        "papillarray_to_uskin": (0.318, 0.581),
    },
}

# Section IV-C: mean contact-geometry error (mm) of the MLP on the 16-d latent, "train sensor -> test sensor".
PAPER_GEOMETRY_MAE_MM: dict[str, float] = {
    "uskin_to_uskin": 0.353,
    "papillarray_to_papillarray": 0.397,
    "uskin_to_papillarray": 0.637,
    "papillarray_to_uskin": 0.666,
}

# Objects the paper keeps out of autoencoder training (all of their data is test data).
PAPER_UNSEEN_OBJECTS: tuple[str, ...] = ("irregular_pla",)

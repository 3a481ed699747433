"""Measured sensitivity of paper 000's hold accuracy (shown by `adcs report`, paper000_control).

Data of :func:`adcs_nodes.tools.reproductions.sensitivity_markdown`, produced by
``python -m sim_node.tools.closed_loop sensitivity scenarios/paper000_control.yaml`` (plain
numpy loop of the project's cores: the graph's trajectory without ROS). A measurement, not a
paper value: refresh it when the cores change.
"""

#: The baseline run (the scenario's own values), listed under both parameters.
_BASELINE_RESULT = {
    "capture_orbits": 5.6917,
    "last_exit_orbits": 5.6917,
    "first_entry_s": 33660.0,
    "hold_rms_deg": 71.0813,
    "hold_median_deg": 51.6907,
    "hold_p95_deg": 134.6058,
    "hold_max_deg": 141.6325,
    "est_err_median_deg": 0.4349,
    "hold_only": {
        "rms_deg": 1.0361,
        "median_deg": 0.7065,
        "p95_deg": 1.7882,
        "max_deg": 1.8695,
        "est_err_median_deg": 0.5768
    }
}

MEASURED = {
    "scenario": "paper000_control",
    "seed": 21,
    "duration_s": 35484.0,
    "hold_only_orbits": 3.0,
    "hold_only_from_orbits": 1.0,
    "baseline": {
        "random_period_s": 0.1,
        "misalignment_deg": 0.0
    },
    "cases": [
        {"parameter": "random_period_s", "value": 0.1, **_BASELINE_RESULT},
        {
            "parameter": "random_period_s",
            "value": 0.5,
            "capture_orbits": None,
            "last_exit_orbits": None,
            "first_entry_s": None,
            "hold_rms_deg": 98.1231,
            "hold_median_deg": 102.5104,
            "hold_p95_deg": 132.9284,
            "hold_max_deg": 136.2517,
            "est_err_median_deg": 0.4288,
            "hold_only": {
                "rms_deg": 1.2259,
                "median_deg": 0.9413,
                "p95_deg": 2.1542,
                "max_deg": 2.5149,
                "est_err_median_deg": 0.6016
            }
        },
        {
            "parameter": "random_period_s",
            "value": 2.0,
            "capture_orbits": 4.1016,
            "last_exit_orbits": None,
            "first_entry_s": 24256.0,
            "hold_rms_deg": 3.3834,
            "hold_median_deg": 1.5243,
            "hold_p95_deg": 6.8268,
            "hold_max_deg": 12.2677,
            "est_err_median_deg": 0.5413,
            "hold_only": {
                "rms_deg": 1.6447,
                "median_deg": 1.2657,
                "p95_deg": 3.0929,
                "max_deg": 3.356,
                "est_err_median_deg": 0.5738
            }
        },
        {"parameter": "misalignment_deg", "value": 0.0, **_BASELINE_RESULT},
        {
            "parameter": "misalignment_deg",
            "value": 0.5,
            "capture_orbits": None,
            "last_exit_orbits": None,
            "first_entry_s": None,
            "hold_rms_deg": 96.8649,
            "hold_median_deg": 100.2883,
            "hold_p95_deg": 130.1902,
            "hold_max_deg": 131.982,
            "est_err_median_deg": 0.6837,
            "hold_only": {
                "rms_deg": 0.9592,
                "median_deg": 0.653,
                "p95_deg": 1.7353,
                "max_deg": 1.7935,
                "est_err_median_deg": 0.7308
            }
        },
        {
            "parameter": "misalignment_deg",
            "value": 1.0,
            "capture_orbits": 2.6514,
            "last_exit_orbits": 3.4641,
            "first_entry_s": 12782.0,
            "hold_rms_deg": 2.2023,
            "hold_median_deg": 1.2572,
            "hold_p95_deg": 4.0837,
            "hold_max_deg": 4.2052,
            "est_err_median_deg": 1.1388,
            "hold_only": {
                "rms_deg": 1.9483,
                "median_deg": 1.3558,
                "p95_deg": 3.4543,
                "max_deg": 3.5467,
                "est_err_median_deg": 1.1036
            }
        },
        {
            "parameter": "misalignment_deg",
            "value": 2.0,
            "capture_orbits": 3.1858,
            "last_exit_orbits": 5.5345,
            "first_entry_s": 18840.0,
            "hold_rms_deg": 4.3449,
            "hold_median_deg": 3.1119,
            "hold_p95_deg": 7.6941,
            "hold_max_deg": 8.2521,
            "est_err_median_deg": 2.0813,
            "hold_only": {
                "rms_deg": 4.3914,
                "median_deg": 3.208,
                "p95_deg": 7.6062,
                "max_deg": 7.9069,
                "est_err_median_deg": 2.0027
            }
        }
    ],
    "note": (
        "Measured on 2026-11-26 (tree of about 13:55 UTC) with `python -m sim_node.tools."
        "closed_loop sensitivity scenarios/paper000_control.yaml`; rerun it and pass the "
        "JSON to `reproductions.sensitivity_markdown` to refresh. The \"from the paper sta"
        "te\" columns are one acquisition each: whether a run gets stuck at 80-140 deg for"
        " orbits changes with tiny perturbations (different random draws), so they do not"
        " order the parameters; the \"on target\" columns do: the hold error grows with the"
        " correlation time (the random torque's power spectral density is std^2 x correla"
        "tion time) and with the misalignment (unmodelled, it biases the estimate).")
}

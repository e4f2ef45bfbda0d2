"""Run EMVA's own reference implementation (the ``emva1288`` package) on an EMVA 1288 descriptor file.

Runs in a virtual environment of its own, without SimSPAD (tests/analysis/test_emva1288_reference.py creates it):
``python emva1288_process.py DESCRIPTOR`` parses the descriptor and its images with ``emva1288.process``
(parser → loader → Data1288 → Results1288, as ``emva1288.process.Emva1288`` does) and prints the results as one
JSON object: system gain K (DN/e⁻), temporal dark noise σ_d (e⁻), quantum efficiency (%), responsivity R (DN/p),
saturation capacity μ_p.sat (photons) and μ_e.sat (e⁻), DSNU (e⁻) and PRNU (%).
"""

import json
import logging
import sys

from emva1288.process import Data1288, LoadImageData, ParseEmvaDescriptorFile, Results1288


def main(descriptor: str) -> None:
    parser = ParseEmvaDescriptorFile(descriptor, loglevel=logging.WARNING)
    images = LoadImageData(parser.images, loglevel=logging.WARNING)
    data = Data1288(images.data, loglevel=logging.WARNING)
    results = Results1288(data.data, loglevel=logging.WARNING)
    out = {"K": results.K, "sigma_d": results.sigma_d, "QE": results.QE, "R": results.R,
           "u_p_sat": results.u_p_sat, "u_e_sat": results.u_e_sat, "DSNU1288": results.DSNU1288,
           "PRNU1288": results.PRNU1288, "index_u_ysat": int(results.index_u_ysat),
           "n_points": int(len(data.data["temporal"]["u_p"]))}
    print(json.dumps({k: float(v) for k, v in out.items()}))


if __name__ == "__main__":
    main(sys.argv[1])

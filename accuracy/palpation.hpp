// Palpation (docs/meshing.md): a block with a spherical
// tumour stiffer than the tissue, meshed conformingly (io/organ_mesher: the
// tumour its own element set and material), and a line scan of the tool
// across the top above it: at each point the tool is pressed a fixed depth
// and held, the block relaxed to equilibrium (accuracy/reference.hpp), and
// the force recorded. The baseline is the same scan over the same mesh with
// the tumour's elements given the tissue's material, so that the difference
// is the tumour's alone (not the mesh's). `tissue palpate` prints, writes
// JSON and a PNG.
#pragma once

#include <string>
#include <vector>

#include "core/vec.hpp"

namespace tissue::accuracy {

struct PalpationOptions {
  double L = 0.06, H = 0.03;        ///< block: L x L wide, H high, bottom fixed (m)
  double tumour_radius = 0.005;     ///< m
  double tumour_depth = 0.010;      ///< its centre below the top (m), under the block's centre
  double E = 3000, nu = 0.45, rho = 1000;  ///< tissue
  double stiffness_ratio = 10;      ///< tumour E / tissue E (same nu and rho)
  double tool_radius = 0.005;       ///< the probe's sphere (m): a fingertip
  double press = 0.003;             ///< how deep the tool is pressed at each point (m)
  int positions = 9;                ///< scan points, evenly from -scan/2 to scan/2 along x through the centre
  double scan = 0.036;              ///< m
  int target_tets = 20000;
  double residual = 1e-4;           ///< each relaxation's relative residual (the force to ~1e-4)
  std::string backend = "cpu";
};

struct PalpationPoint {
  double x = 0;                     ///< scan coordinate (m, 0 above the tumour)
  Vec3<double> force = {};          ///< on the tool (N)
};

struct PalpationScan {
  long nodes = 0, tets = 0, tumour_tets = 0;
  std::vector<PalpationPoint> with, without;  ///< the scan with the tumour and the baseline, point by point
};

/// Meshes the block with the tumour and runs both scans. Throws
/// std::invalid_argument for a tumour outside the block or a press that
/// reaches it, io::MeshError / ModelError from meshing and the model.
PalpationScan run_palpation(const PalpationOptions& options);

}  // namespace tissue::accuracy

#include "scene/scene.hpp"

#include <algorithm>

namespace tissue::scene {

MaterialParams Material::params() const {
  MaterialParams p;
  switch (form) {
    case Form::YoungPoisson:
      p.mu = a / (2 * (1 + b));
      p.K = a / (3 * (1 - 2 * b));
      break;
    case Form::ShearBulk:
      p.mu = a;
      p.K = b;
      break;
    case Form::Lame:
      p.mu = b;
      p.K = a + 2 * b / 3;
      break;
  }
  p.rho = rho;
  p.fibre_eta = fibre_eta;
  p.fibre_dir = fibre_dir;
  p.prony_terms = int(std::min<size_t>(prony.size(), kMaxProny));
  for (int i = 0; i < p.prony_terms; ++i) {
    p.prony_g[i] = prony[i].g;
    p.prony_tau[i] = prony[i].tau;
  }
  return p;
}

}  // namespace tissue::scene

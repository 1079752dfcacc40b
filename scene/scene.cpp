#include "scene/scene.hpp"

namespace tissue::scene {

MaterialParams Material::params() const {
  switch (form) {
    case Form::YoungPoisson:
      return {a / (2 * (1 + b)), a / (3 * (1 - 2 * b)), rho};
    case Form::ShearBulk:
      return {a, b, rho};
    case Form::Lame:
      return {b, a + 2 * b / 3, rho};
  }
  return {};
}

}  // namespace tissue::scene

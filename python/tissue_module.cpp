// tissue._tissue: the Python bindings of the embedding facade
// (tissue/simulation.hpp; docs/python.md). Arrays are NumPy arrays:
// - the reference mesh (rest positions, tetrahedra, surface triangles) is a
//   read-only view of the Simulation's own memory (no copy; the array keeps
//   the Simulation alive);
// - fields are new arrays that the engine writes straight into (one copy,
//   from the tick's download);
// - meshes made by mesh_surface hand their buffers to NumPy (no copy).
// step() releases the GIL while the ticks run.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "tissue/simulation.hpp"

namespace py = pybind11;
using tissue::Field;
using tissue::Simulation;

namespace {

/// A NumPy array of shape (n / cols, cols) (or (n,) for cols = 1) owning v.
template <class T>
py::array_t<T> owned(std::vector<T>&& v, py::ssize_t cols) {
  auto* heap = new std::vector<T>(std::move(v));
  py::capsule free_it(heap, [](void* p) { delete static_cast<std::vector<T>*>(p); });
  const py::ssize_t n = py::ssize_t(heap->size());
  if (cols == 1) return py::array_t<T>({n}, heap->data(), free_it);
  return py::array_t<T>({n / cols, cols}, heap->data(), free_it);
}

/// A read-only (n / cols, cols) view of memory `owner` keeps alive.
template <class T>
py::array_t<T> view(std::span<const T> s, py::ssize_t cols, py::handle owner) {
  py::array_t<T> a({py::ssize_t(s.size()) / cols, cols}, s.data(), owner);
  a.attr("setflags")(py::arg("write") = false);
  return a;
}

/// A new array the engine fills with the field.
py::array_t<double> field_array(Simulation& s, Field f) {
  const int c = tissue::field_components(f);
  const py::ssize_t n = py::ssize_t(f == Field::Jacobian ? s.n_elements() : s.n_nodes());
  py::array_t<double> a = c == 1 ? py::array_t<double>({n}) : py::array_t<double>({n, py::ssize_t(c)});
  s.read_field(f, {a.mutable_data(), std::size_t(a.size())});
  return a;
}

tissue::Vector3 vector3(py::handle v, const char* what) {
  const auto a = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(v);
  if (!a || a.size() != 3) throw std::invalid_argument(std::string(what) + " must be 3 numbers (x, y, z)");
  return {a.at(0), a.at(1), a.at(2)};
}

py::array_t<double> numpy3(const tissue::Vector3& v) {
  py::array_t<double> a(3);
  for (int c = 0; c < 3; ++c) a.mutable_at(c) = v[c];
  return a;
}

tissue::SimulationOptions options(const std::optional<std::string>& backend, const std::optional<std::string>& precision,
                                  const std::optional<std::string>& depth) {
  return {backend.value_or(""), precision.value_or(""), depth.value_or("")};
}

/// Copies an (n, cols) array-like of numbers into a flat vector, naming the argument when its shape is wrong.
template <class T>
std::vector<T> flat(py::handle a, py::ssize_t cols, const char* what) {
  const auto arr = py::array_t<T, py::array::c_style | py::array::forcecast>::ensure(a);
  if (!arr) throw std::invalid_argument(std::string(what) + " must be an array of numbers");
  if (cols > 1 && (arr.ndim() != 2 || arr.shape(1) != cols))
    throw std::invalid_argument(std::string(what) + " must have shape (n, " + std::to_string(cols) + "), not " +
                                std::string(py::str(py::getattr(arr, "shape"))));
  if (cols == 1 && arr.ndim() != 1)
    throw std::invalid_argument(std::string(what) + " must be one-dimensional");
  return {arr.data(), arr.data() + arr.size()};
}

}  // namespace

PYBIND11_MODULE(_tissue, m) {
  m.doc() = "Tissue: nonlinear soft-tissue deformation (TLED, Neo-Hookean) with tool contact and haptic forces";
  m.attr("__version__") = tissue::version();
  m.def("available_backends", &tissue::available_backends, "Backends built in and usable on this machine");

  py::class_<tissue::VolumeMeshResult>(m, "VolumeMesh", "A tetrahedral mesh made by mesh_surface")
      .def_property_readonly("nodes", [](py::object self) {
        auto& r = self.cast<tissue::VolumeMeshResult&>();
        return view<double>(r.nodes, 3, self);
      }, "(n_nodes, 3) positions (m)")
      .def_property_readonly("tets", [](py::object self) {
        auto& r = self.cast<tissue::VolumeMeshResult&>();
        return view<std::int32_t>(r.tets, 4, self);
      }, "(n_tets, 4) node ids")
      .def_readonly("quality", &tissue::VolumeMeshResult::quality, "The quality report")
      .def("__repr__", [](const tissue::VolumeMeshResult& r) {
        return "<tissue.VolumeMesh " + std::to_string(r.nodes.size() / 3) + " nodes, " +
               std::to_string(r.tets.size() / 4) + " tets>";
      });
  m.def("mesh_surface", [](const std::string& path, const std::string& unit, int target_tets) {
    py::gil_scoped_release free;
    return tissue::mesh_surface(path, unit, target_tets);
  }, py::arg("path"), py::arg("unit") = "m", py::arg("target_tets") = 0,
        "Repair, remesh and tetrahedralise a closed surface file (OBJ, STL, PLY, OFF, ...)");

  py::class_<tissue::ToolResult>(m, "ToolResult", "One tool at the end of a tick")
      .def_property_readonly("tip", [](const tissue::ToolResult& t) { return numpy3(t.tip); })
      .def_property_readonly("axis", [](const tissue::ToolResult& t) { return numpy3(t.axis); })
      .def_property_readonly("force", [](const tissue::ToolResult& t) { return numpy3(t.force); },
                             "Force on the tool (N): what the hand feels")
      .def_readonly("contact_nodes", &tissue::ToolResult::contact_nodes)
      .def_readonly("grasped_nodes", &tissue::ToolResult::grasped_nodes)
      .def_readonly("grasp", &tissue::ToolResult::grasp);

  py::class_<tissue::TickResult>(m, "TickResult", "What one haptic tick did")
      .def_readonly("tick", &tissue::TickResult::tick)
      .def_readonly("time", &tissue::TickResult::time)
      .def_readonly("steps", &tissue::TickResult::steps)
      .def_readonly("tools", &tissue::TickResult::tools)
      .def_readonly("max_displacement", &tissue::TickResult::max_displacement)
      .def_readonly("residual", &tissue::TickResult::residual)
      .def_readonly("equilibrium", &tissue::TickResult::equilibrium)
      .def_readonly("region_nodes", &tissue::TickResult::region_nodes)
      .def_readonly("region_elements", &tissue::TickResult::region_elements)
      .def("__repr__", [](const tissue::TickResult& r) {
        std::string s = "<tissue.TickResult tick " + std::to_string(r.tick) + ", t = " + std::to_string(r.time) + " s";
        for (const auto& t : r.tools)
          s += ", force (" + std::to_string(t.force[0]) + ", " + std::to_string(t.force[1]) + ", " +
               std::to_string(t.force[2]) + ") N";
        return s + ">";
      });

  py::class_<Simulation>(m, "Simulation", "A scene running on a backend, driven tick by tick")
      .def_static("load", [](const std::string& scene, std::optional<std::string> backend,
                             std::optional<std::string> precision, std::optional<std::string> depth) {
        py::gil_scoped_release free;
        return Simulation::load(scene, options(backend, precision, depth));
      }, py::arg("scene"), py::arg("backend") = py::none(), py::arg("precision") = py::none(),
                  py::arg("depth") = py::none(), "Load a scene file or '@kidney'")
      .def_static("from_mesh", [](py::handle nodes, py::handle tets, double E, double nu, double rho, py::handle fixed,
                                  std::vector<double> tool_radii, double tool_shaft, std::optional<std::string> backend,
                                  std::optional<std::string> precision, std::optional<std::string> depth,
                                  std::string name) {
        tissue::MeshScene s;
        s.name = std::move(name);
        s.nodes = flat<double>(nodes, 3, "nodes");
        s.tets = flat<std::int32_t>(tets, 4, "tets");
        s.youngs_modulus = E;
        s.poisson_ratio = nu;
        s.density = rho;
        if (!fixed.is_none()) s.fixed_nodes = flat<std::int32_t>(fixed, 1, "fixed");
        s.tool_radii = std::move(tool_radii);
        s.tool_shaft = tool_shaft;
        py::gil_scoped_release free;
        return Simulation::from_mesh(s, options(backend, precision, depth));
      }, py::arg("nodes"), py::arg("tets"), py::kw_only(), py::arg("E") = 3000.0, py::arg("nu") = 0.45,
                  py::arg("rho") = 1000.0, py::arg("fixed") = py::none(),
                  py::arg("tool_radii") = std::vector<double>{2e-3}, py::arg("tool_shaft") = 0.0,
                  py::arg("backend") = py::none(), py::arg("precision") = py::none(), py::arg("depth") = py::none(),
                  py::arg("name") = "<mesh>", "Build a simulation of a tetrahedral mesh with one material")
      .def_property_readonly("name", &Simulation::name)
      .def_property_readonly("backend", &Simulation::backend)
      .def_property_readonly("precision", &Simulation::precision)
      .def_property_readonly("device_name", &Simulation::device_name)
      .def_property_readonly("n_nodes", &Simulation::n_nodes)
      .def_property_readonly("n_elements", &Simulation::n_elements)
      .def_property_readonly("n_tools", &Simulation::n_tools)
      .def_property_readonly("tick_seconds", &Simulation::tick_seconds)
      .def_property_readonly("steps_per_tick", &Simulation::steps_per_tick)
      .def_property_readonly("dt", &Simulation::dt)
      .def_property_readonly("warnings", &Simulation::warnings)
      .def_property_readonly("ticks", &Simulation::ticks)
      .def_property_readonly("time", &Simulation::time)
      .def_property_readonly("rest_positions", [](py::object self) {
        return view<double>(self.cast<Simulation&>().rest_positions(), 3, self);
      }, "(n_nodes, 3) reference positions (m), a read-only view")
      .def_property_readonly("tetrahedra", [](py::object self) {
        return view<std::int32_t>(self.cast<Simulation&>().tetrahedra(), 4, self);
      }, "(n_elements, 4) node ids, a read-only view")
      .def_property_readonly("surface_triangles", [](py::object self) {
        return view<std::int32_t>(self.cast<Simulation&>().surface_triangles(), 3, self);
      }, "(n_triangles, 3) outward surface triangles, a read-only view")
      .def("set_tool_pose", [](Simulation& s, int tool, py::handle tip, py::handle axis) {
        s.set_tool_pose(tool, vector3(tip, "tip"), axis.is_none() ? tissue::Vector3{0, 0, 0} : vector3(axis, "axis"));
      }, py::arg("tool"), py::arg("tip"), py::arg("axis") = py::none(),
           "The pose the tool reaches at the end of the next tick (m); the host drives the tool from now on")
      .def("set_grasp", &Simulation::set_grasp, py::arg("tool"), py::arg("down"))
      .def("follow_scene_path", &Simulation::follow_scene_path, py::arg("tool"))
      .def("tool_radius", &Simulation::tool_radius, py::arg("tool"))
      .def("tool_shaft", &Simulation::tool_shaft, py::arg("tool"))
      .def("step", &Simulation::step, py::arg("ticks") = 1, py::call_guard<py::gil_scoped_release>(),
           "Run haptic ticks; returns the last one's TickResult")
      .def_property_readonly("last", &Simulation::last)
      .def("force", [](const Simulation& s, int tool) { return numpy3(s.force(tool)); }, py::arg("tool") = 0,
           "Force on the tool after the last tick (N)")
      .def("reset", &Simulation::reset, "Back to rest (u = 0, tick 0); keeps the loads")
      .def(
          "set_loads",
          [](Simulation& s, py::array_t<std::int32_t, py::array::c_style | py::array::forcecast> nodes,
             py::array_t<double, py::array::c_style | py::array::forcecast> forces) {
            if (forces.size() != 3 * nodes.size())
              throw std::invalid_argument("set_loads: forces must hold 3 values (x y z, N) per node: " +
                                          std::to_string(forces.size()) + " values for " +
                                          std::to_string(nodes.size()) + " nodes");
            s.set_loads(std::span<const std::int32_t>(nodes.data(), std::size_t(nodes.size())),
                        std::span<const double>(forces.data(), std::size_t(forces.size())));
          },
          py::arg("nodes"), py::arg("forces"),
          "Constant external forces (N) from the next tick on: nodes (n,), forces (n, 3); replaces the scene's "
          "loads; empty arrays remove them")
      .def("dissipated_energy", &Simulation::dissipated_energy,
           "J dissipated by the viscoelastic (Prony) terms since the start")
      .def("viscous_stored_energy", &Simulation::viscous_stored_energy,
           "J stored in the Prony terms' branches after the last tick")
      .def("take_notes", &Simulation::take_notes)
      .def("displacement", [](Simulation& s) { return field_array(s, Field::Displacement); }, "(n_nodes, 3) m")
      .def("positions", [](Simulation& s) { return field_array(s, Field::Position); }, "(n_nodes, 3) X + u (m)")
      .def("pressure", [](Simulation& s) { return field_array(s, Field::Pressure); }, "(n_nodes,) Pa")
      .def("internal_force", [](Simulation& s) { return field_array(s, Field::InternalForce); }, "(n_nodes, 3) N")
      .def("jacobian", [](Simulation& s) { return field_array(s, Field::Jacobian); }, "(n_elements,) J = det F")
      .def("positions_f32", [](Simulation& s) {
        if (s.positions_on_device())
          throw std::invalid_argument("positions_f32: the " + s.backend() +
                                      " backend writes positions to device memory; use positions()");
        py::array_t<float> a({py::ssize_t(s.n_nodes()), py::ssize_t(3)});
        s.write_positions(a.mutable_data());
        return a;
      }, "(n_nodes, 3) float32 deformed positions written straight from the store (host backends)")
      .def("__repr__", [](const Simulation& s) {
        return "<tissue.Simulation " + s.name() + ": " + std::to_string(s.n_nodes()) + " nodes, " +
               std::to_string(s.n_elements()) + " tets on " + s.backend() + " (" + s.precision() + ")>";
      });
}

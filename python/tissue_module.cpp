// tissue._tissue: the Python bindings of the embedding facade
// (tissue/simulation.hpp; docs/python.md). Arrays are NumPy arrays:
// - the reference mesh (rest positions, tetrahedra, surface triangles) is a
//   read-only view of the Simulation's own memory (no copy; the array keeps
//   the Simulation alive);
// - fields are new arrays that the engine writes straight into (one copy,
//   from the tick's download);
// - meshes made by mesh_surface hand their buffers to NumPy (no copy).
// A Simulation or Batch holds a lock that every call takes, so Python threads
// sharing one take turns; step() releases the GIL while the ticks run and
// lets Python handle signals between ticks (Ctrl-C raises KeyboardInterrupt
// at a tick boundary).
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <chrono>
#include <climits>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <tuple>
#include <vector>

#include "tissue/batch.hpp"
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

/// A read-only (n / cols, cols) view of memory `owner` keeps alive ((n,) for cols = 1).
template <class T>
py::array_t<T> view(std::span<const T> s, py::ssize_t cols, py::handle owner) {
  py::array_t<T> a = cols == 1 ? py::array_t<T>({py::ssize_t(s.size())}, s.data(), owner)
                               : py::array_t<T>({py::ssize_t(s.size()) / cols, cols}, s.data(), owner);
  a.attr("setflags")(py::arg("write") = false);
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

/// Node ids from an array-like of shape (n, cols) (or (n,) for cols = 1):
/// integers, or floats holding whole numbers, within the int32 range of the
/// engine's ids. A fraction, a NaN or an id beyond int32 is refused naming
/// the argument, the index and the value (a plain cast would truncate or
/// wrap it into another, valid-looking node).
std::vector<std::int32_t> node_ids(py::handle h, py::ssize_t cols, const char* what) {
  const py::array a = py::array::ensure(h);
  if (!a) throw std::invalid_argument(std::string(what) + " must be an array of node ids");
  if (cols > 1 && (a.ndim() != 2 || a.shape(1) != cols))
    throw std::invalid_argument(std::string(what) + " must have shape (n, " + std::to_string(cols) + "), not " +
                                std::string(py::str(py::getattr(a, "shape"))));
  if (cols == 1 && a.ndim() != 1) throw std::invalid_argument(std::string(what) + " must be one-dimensional");
  const auto where = [&](py::ssize_t i) {
    const std::string index = cols > 1 ? std::to_string(i / cols) + ", " + std::to_string(i % cols) : std::to_string(i);
    return std::string(what) + "[" + index + "]";
  };
  const auto out_of_range = [&](py::ssize_t i, const std::string& value) {
    return std::invalid_argument(where(i) + " = " + value + " is outside the range of node ids (" +
                                 std::to_string(INT32_MIN) + " .. " + std::to_string(INT32_MAX) + ")");
  };
  std::vector<std::int32_t> out(std::size_t(a.size()));
  const char kind = a.dtype().kind();
  if (kind == 'i') {
    const auto v = py::array_t<std::int64_t, py::array::c_style | py::array::forcecast>::ensure(a);
    for (py::ssize_t i = 0; i < v.size(); ++i) {
      const std::int64_t x = v.data()[i];
      if (x < INT32_MIN || x > INT32_MAX) throw out_of_range(i, std::to_string(x));
      out[std::size_t(i)] = std::int32_t(x);
    }
  } else if (kind == 'u') {
    const auto v = py::array_t<std::uint64_t, py::array::c_style | py::array::forcecast>::ensure(a);
    for (py::ssize_t i = 0; i < v.size(); ++i) {
      const std::uint64_t x = v.data()[i];
      if (x > std::uint64_t(INT32_MAX)) throw out_of_range(i, std::to_string(x));
      out[std::size_t(i)] = std::int32_t(x);
    }
  } else if (kind == 'f') {
    const auto v = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(a);
    for (py::ssize_t i = 0; i < v.size(); ++i) {
      const double x = v.data()[i];
      const auto value = [x] { return std::string(py::repr(py::float_(x))); };
      if (!(std::floor(x) == x))
        throw std::invalid_argument(where(i) + " = " + value() + " is not a whole number (a node id)");
      if (x < INT32_MIN || x > INT32_MAX) throw out_of_range(i, value());
      out[std::size_t(i)] = std::int32_t(x);
    }
  } else if (kind == 'O') {  // Python ints beyond 64 bits, or mixed objects
    const py::list items = a.attr("ravel")().attr("tolist")();
    for (py::ssize_t i = 0; i < py::ssize_t(items.size()); ++i) {
      const py::handle x = items[std::size_t(i)];
      if (!py::isinstance<py::int_>(x) || py::isinstance<py::bool_>(x))
        throw std::invalid_argument(where(i) + " = " + std::string(py::repr(x)) + " is not an integer (a node id)");
      int overflow = 0;
      const long long id = PyLong_AsLongLongAndOverflow(x.ptr(), &overflow);
      if (overflow != 0 || id < INT32_MIN || id > INT32_MAX) throw out_of_range(i, py::str(x));
      out[std::size_t(i)] = std::int32_t(id);
    }
  } else {
    throw std::invalid_argument(std::string(what) + " must hold integer node ids, not " +
                                std::string(py::str(a.dtype())) + " values");
  }
  return out;
}

/// A Python int (or anything with __index__) as a tick count; a value beyond
/// a C long is refused naming it and the range (the engine's own check
/// refuses counts below 1).
long tick_count(py::handle h) {
  const py::object i = py::reinterpret_steal<py::object>(PyNumber_Index(h.ptr()));
  if (!i) {
    PyErr_Clear();
    throw py::type_error("step(ticks=" + std::string(py::repr(h)) + "): the tick count must be an integer");
  }
  int overflow = 0;
  const long long n = PyLong_AsLongLongAndOverflow(i.ptr(), &overflow);
  if (overflow != 0 || n < LONG_MIN || n > LONG_MAX)
    throw std::invalid_argument("step(ticks=" + std::string(py::str(i)) + "): the tick count is outside 1 .. " +
                                std::to_string(LONG_MAX));
  return long(n);
}

/// Runs `ticks` ticks as calls run(n) of kTicksPerCall ticks or fewer, the
/// caller having released the GIL. Between calls, at most every
/// kSignalInterval, it takes the GIL and lets Python handle signals: Ctrl-C
/// (KeyboardInterrupt) then ends a long step at a tick boundary, the
/// simulation consistent and able to step on. A count below 1 goes to run()
/// whole, for the engine to refuse.
constexpr long kTicksPerCall = 10;
constexpr auto kSignalInterval = std::chrono::milliseconds(50);

template <class Run>
auto interruptible(long ticks, Run&& run) {
  if (ticks < 1) return run(ticks);
  using Clock = std::chrono::steady_clock;
  auto checked = Clock::now();
  for (long done = 0;;) {
    const long n = std::min(kTicksPerCall, ticks - done);
    auto r = run(n);
    done += n;
    if (done == ticks) return r;
    if (Clock::now() - checked >= kSignalInterval) {
      py::gil_scoped_acquire gil;
      if (PyErr_CheckSignals() != 0) throw py::error_already_set();
      checked = Clock::now();
    }
  }
}

/// Element updates (ticks x steps per tick x elements) one step() call may
/// take unless forced: tissue run's limit (scene::kMaxElementSteps).
constexpr double kMaxElementUpdates = 1e12;

/// The command line's rule (tissue run --force, scene/checks.hpp): beyond
/// kMaxElementUpdates a call takes hours even on a GPU, most likely a slip.
/// per_tick: "S TLED steps x E elements" as the message shows it, updates
/// per tick its value (summed over a batch's scenes).
void check_work(long ticks, double updates_per_tick, const std::string& per_tick, bool force) {
  const double updates = double(ticks) * updates_per_tick;
  if (force || !(updates > kMaxElementUpdates)) return;
  char estimate[64];
  std::snprintf(estimate, sizeof estimate, "%.3g element updates, beyond the %.0e", updates, kMaxElementUpdates);
  throw std::invalid_argument("step(ticks=" + std::to_string(ticks) + "): " + std::to_string(ticks) + " ticks x " +
                              per_tick + " = " + estimate +
                              " a call may take without force=True (hours even on a GPU; a laptop CPU does ~1e8 per "
                              "second); pass fewer ticks, or force=True to run it anyway");
}

/// A Simulation or a Batch with a lock: every call that reads or changes the
/// state holds it, so Python threads sharing one take turns and a read never
/// lands inside a tick (step() releases the GIL, not the lock). What is fixed
/// when it is made (sizes, names, the reference mesh, the tools' shapes, the
/// warnings) is read without it.
/// A Simulation's reference mesh as NumPy arrays, copied once per mesh
/// version (Simulation::mesh_version): arrays handed out before a cut keep
/// the mesh they were made of.
struct MeshArrays {
  std::uint64_t version = 0;
  py::object rest, tets, tris;
};

template <class T>
struct Locked {
  T value;
  std::mutex lock;
  MeshArrays mesh = {};  ///< a Simulation's (mesh_arrays); unused by a Batch
};
using PySimulation = Locked<Simulation>;
using PyBatch = Locked<tissue::Batch>;

/// Runs f(value) holding the object's lock, the GIL released while waiting and working.
template <class T, class F>
auto locked(Locked<T>& o, F&& f) {
  py::gil_scoped_release free;
  std::lock_guard<std::mutex> hold(o.lock);
  return f(o.value);
}

/// A read-only (rows, cols) array of its own copy of `values`.
template <class V>
py::array read_only_copy(const std::vector<V>& values, py::ssize_t cols) {
  py::array_t<V> a({py::ssize_t(values.size()) / cols, cols});
  std::copy(values.begin(), values.end(), a.mutable_data());
  a.attr("flags").attr("writeable") = false;
  return std::move(a);
}

/// The simulation's reference mesh as arrays, made again when the mesh changed.
const MeshArrays& mesh_arrays(PySimulation& s) {
  std::uint64_t version = 0;
  std::vector<double> rest;
  std::vector<std::int32_t> tets, tris;
  locked(s, [&](Simulation& x) {
    version = x.mesh_version();
    if (version == s.mesh.version) return;
    rest.assign(x.rest_positions().begin(), x.rest_positions().end());
    tets.assign(x.tetrahedra().begin(), x.tetrahedra().end());
    tris.assign(x.surface_triangles().begin(), x.surface_triangles().end());
  });
  if (version != s.mesh.version) {
    s.mesh.rest = read_only_copy(rest, 3);
    s.mesh.tets = read_only_copy(tets, 4);
    s.mesh.tris = read_only_copy(tris, 3);
    s.mesh.version = version;
  }
  return s.mesh;
}

/// A new array the engine fills with the field.
py::array_t<double> field_array(PySimulation& s, Field f) {
  const int c = tissue::field_components(f);
  const py::ssize_t n = py::ssize_t(tissue::field_per_element(f) ? s.value.n_elements() : s.value.n_nodes());
  py::array_t<double> a = c == 1 ? py::array_t<double>({n}) : py::array_t<double>({n, py::ssize_t(c)});
  double* out = a.mutable_data();
  const std::size_t size = std::size_t(a.size());
  locked(s, [&](Simulation& x) { x.read_field(f, {out, size}); });
  return a;
}


/// Every scene's field as (N, nodes[, components]) (scenes of one size).
py::array_t<double> batch_field(PyBatch& b, Field f) {
  const int c = tissue::field_components(f);
  const py::ssize_t n = py::ssize_t(b.value.size());
  const py::ssize_t per = py::ssize_t(tissue::field_per_element(f) ? b.value.n_elements(0) : b.value.n_nodes(0));
  py::array_t<double> a = c == 1 ? py::array_t<double>({n, per}) : py::array_t<double>({n, per, py::ssize_t(c)});
  double* out = a.mutable_data();
  const std::size_t size = std::size_t(a.size());
  locked(b, [&](tissue::Batch& batch) { batch.read_fields(f, {out, size}); });
  return a;
}

/// One scene's field as (nodes[, components]).
py::array_t<double> scene_field(PyBatch& b, int scene, Field f) {
  const int c = tissue::field_components(f);
  const py::ssize_t per = py::ssize_t(tissue::field_per_element(f) ? b.value.n_elements(scene) : b.value.n_nodes(scene));
  py::array_t<double> a = c == 1 ? py::array_t<double>({per}) : py::array_t<double>({per, py::ssize_t(c)});
  double* out = a.mutable_data();
  const std::size_t size = std::size_t(a.size());
  locked(b, [&](tissue::Batch& batch) { batch.read_field(scene, f, {out, size}); });
  return a;
}

/// field(scene=None): every scene's (N, ...) or one scene's.
py::array_t<double> any_field(PyBatch& b, std::optional<int> scene, Field f) {
  return scene ? scene_field(b, *scene, f) : batch_field(b, f);
}

/// Body contacts as a dict of new arrays: "node" (n,) int32, "triangle"
/// (n, 3) int32, "body" and "other_body" (n,) int32, "depth" (n,) float64.
py::dict body_contact_arrays(const std::vector<tissue::BodyContact>& contacts) {
  const py::ssize_t n = py::ssize_t(contacts.size());
  py::array_t<std::int32_t> node({n}), triangle({n, py::ssize_t(3)}), body({n}), other({n});
  py::array_t<double> depth({n});
  auto nd = node.mutable_unchecked<1>();
  auto tr = triangle.mutable_unchecked<2>();
  auto bd = body.mutable_unchecked<1>();
  auto ot = other.mutable_unchecked<1>();
  auto dp = depth.mutable_unchecked<1>();
  for (py::ssize_t i = 0; i < n; ++i) {
    const tissue::BodyContact& c = contacts[std::size_t(i)];
    nd(i) = c.node;
    for (py::ssize_t k = 0; k < 3; ++k) tr(i, k) = c.triangle[std::size_t(k)];
    bd(i) = c.body;
    ot(i) = c.other_body;
    dp(i) = c.depth;
  }
  py::dict d;
  d["node"] = node;
  d["triangle"] = triangle;
  d["body"] = body;
  d["other_body"] = other;
  d["depth"] = depth;
  return d;
}

constexpr const char* kBodyContactsDoc =
    "The surface nodes inside another body after the last tick (its last TLED step, before that step's "
    "correction; a scene's <contact bodies>), ascending node id: a dict of new arrays, 'node' (n,) int32, "
    "'triangle' (n, 3) int32 (the other body's surface triangle it was inside: its corners' node ids), 'body' and "
    "'other_body' (n,) int32 (the node's and the triangle's, indices into bodies), 'depth' (n,) float64 (m, how "
    "far inside); n = 0 before the first step and for a scene without body contact";

/// One exported field (tissue/fields.h) as the Python methods present it.
struct FieldMethod {
  const char* name;
  Field field;
  std::string per;    ///< "nodes" or "elements"
  int components;     ///< 3 or 1
  const char* unit;   ///< "m"
  const char* what;   ///< "displacement u"
  std::string doc() const { return std::string(unit) + ": " + what; }
};

std::vector<FieldMethod> field_methods() {
  std::vector<FieldMethod> out;
#define TISSUE_FIELD_METHOD(c_name, cpp_name, python, per, components, unit, what)                       \
  out.push_back({#python, Field::cpp_name, std::string_view(#per) == "ELEMENT" ? "elements" : "nodes", components, \
                 unit, what});
  TISSUE_FIELD_LIST(TISSUE_FIELD_METHOD)
#undef TISSUE_FIELD_METHOD
  return out;
}

/// A Simulation's method per field: f() -> (n, components) or (n,).
void bind_simulation_fields(py::class_<PySimulation>& cls) {
  for (const FieldMethod& m : field_methods()) {
    const Field f = m.field;
    const std::string shape = "(n_" + m.per + (m.components == 1 ? ",)" : ", 3)");
    cls.def(m.name, [f](PySimulation& s) { return field_array(s, f); }, (shape + " " + m.doc()).c_str());
  }
}

/// A Batch's method per field: f(scene=None) -> every scene's (N, n, ...) or one scene's.
void bind_batch_fields(py::class_<PyBatch>& cls) {
  for (const FieldMethod& m : field_methods()) {
    const Field f = m.field;
    cls.def(m.name, [f](PyBatch& b, std::optional<int> s) { return any_field(b, s, f); },
            py::arg("scene") = py::none(),
            ("(N, " + m.per + (m.components == 1 ? ")" : ", 3)") + " " + m.doc() + "; or one scene's").c_str());
  }
}

/// The module, its functions and the meshes mesh_surface makes.
void bind_module(py::module_& m) {
  m.doc() = "Tissue: nonlinear soft-tissue deformation (TLED, Neo-Hookean) with tool contact and haptic forces";
  m.attr("__version__") = tissue::version();
  m.def("available_backends", &tissue::available_backends, "Backends built in and usable on this machine");
  m.def("fields", [] {
    py::list out;
    for (const FieldMethod& f : field_methods())
      out.append(py::make_tuple(f.name, f.per, f.components, f.unit, f.what));
    return out;
  }, "The exported fields (tissue/fields.h): (method, 'nodes' | 'elements', components, unit, what) each; "
     "Simulation and Batch have a method of each name");

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
  py::class_<tissue::CutMeshResult>(m, "CutMesh", "A mesh cut where a blade sweeps (cut_mesh; docs/cutting.md)")
      .def_property_readonly("nodes", [](py::object self) {
        return view<double>(self.cast<tissue::CutMeshResult&>().nodes, 3, self);
      }, "(n_nodes, 3) positions (m)")
      .def_property_readonly("tets", [](py::object self) {
        return view<std::int32_t>(self.cast<tissue::CutMeshResult&>().tets, 4, self);
      }, "(n_tets, 4) node ids")
      .def_property_readonly("node_from", [](py::object self) {
        return view<std::int32_t>(self.cast<tissue::CutMeshResult&>().node_from, 2, self);
      }, "(n_nodes, 2): the input nodes each lies between (the same twice: kept or copied)")
      .def_property_readonly("weight", [](py::object self) {
        return view<double>(self.cast<tissue::CutMeshResult&>().weight, 1, self);
      }, "(n_nodes,): each node's place between them, (1 - w) X_a + w X_b")
      .def_property_readonly("element_from", [](py::object self) {
        return view<std::int32_t>(self.cast<tissue::CutMeshResult&>().element_from, 1, self);
      }, "(n_tets,): the input element each is (part of)")
      .def_readonly("elements_split", &tissue::CutMeshResult::pieces_split)
      .def_readonly("nodes_snapped", &tissue::CutMeshResult::nodes_snapped)
      .def_readonly("nodes_copied", &tissue::CutMeshResult::nodes_copied)
      .def_readonly("faces_opened", &tissue::CutMeshResult::faces_opened)
      .def_readonly("left_whole", &tissue::CutMeshResult::left_whole)
      .def("__repr__", [](const tissue::CutMeshResult& r) {
        return "<tissue.CutMesh " + std::to_string(r.nodes.size() / 3) + " nodes, " + std::to_string(r.tets.size() / 4) +
               " tets, " + std::to_string(r.faces_opened) + " faces opened>";
      });
  m.def("cut_mesh", [](py::handle nodes, py::handle tets, py::handle origin, py::handle edge, py::handle sweep,
                       const std::string& method) {
    const std::vector<double> x = flat<double>(nodes, 3, "nodes");
    const std::vector<std::int32_t> t = node_ids(tets, 4, "tets");
    const tissue::Vector3 o = vector3(origin, "origin"), e = vector3(edge, "edge"), w = vector3(sweep, "sweep");
    py::gil_scoped_release free;
    return tissue::cut_mesh(x, t, o, e, w, method);
  }, py::arg("nodes"), py::arg("tets"), py::arg("origin"), py::arg("edge"), py::arg("sweep"),
        py::arg("method") = "snap-split",
        "Cut a tetrahedral mesh where a blade sweeps: the parallelogram origin + s edge + t sweep (m)");
  m.def("mesh_surface", [](const std::string& path, const std::string& unit, int target_tets) {
    py::gil_scoped_release free;
    return tissue::mesh_surface(path, unit, target_tets);
  }, py::arg("path"), py::arg("unit") = "m", py::arg("target_tets") = 0,
        "Repair, remesh and tetrahedralise a closed surface file (OBJ, STL, PLY, OFF, ...)");
}

/// What a tick gives back: TickResult and ToolResult.
void bind_results(py::module_& m) {
  py::class_<tissue::CutStats>(m, "CutStats", "What Simulation.cut did (docs/cutting.md)")
      .def_readonly("nodes_before", &tissue::CutStats::nodes_before)
      .def_readonly("elements_before", &tissue::CutStats::elements_before)
      .def_readonly("nodes", &tissue::CutStats::nodes)
      .def_readonly("elements", &tissue::CutStats::elements)
      .def_readonly("elements_split", &tissue::CutStats::pieces_split)
      .def_readonly("nodes_snapped", &tissue::CutStats::nodes_snapped)
      .def_readonly("nodes_copied", &tissue::CutStats::nodes_copied)
      .def_readonly("faces_opened", &tissue::CutStats::faces_opened)
      .def_readonly("left_whole", &tissue::CutStats::left_whole)
      .def_readonly("dt_before", &tissue::CutStats::dt_before, "TLED step before the cut (s)")
      .def_readonly("dt_after", &tissue::CutStats::dt_after, "TLED step after it (s)")
      .def("__repr__", [](const tissue::CutStats& c) {
        return "<tissue.CutStats " + std::to_string(c.nodes_before) + " -> " + std::to_string(c.nodes) + " nodes, " +
               std::to_string(c.elements_before) + " -> " + std::to_string(c.elements) + " elements, " +
               std::to_string(c.faces_opened) + " faces opened>";
      });
  py::class_<tissue::BodyRange>(m, "Body",
                                "One body of a scene: its nodes and elements, consecutive ranges of the scene's")
      .def_readonly("name", &tissue::BodyRange::name)
      .def_readonly("first_node", &tissue::BodyRange::first_node)
      .def_readonly("n_nodes", &tissue::BodyRange::n_nodes)
      .def_readonly("first_element", &tissue::BodyRange::first_element)
      .def_readonly("n_elements", &tissue::BodyRange::n_elements)
      .def_property_readonly("nodes", [](const tissue::BodyRange& b) {
        return py::slice(py::ssize_t(b.first_node), py::ssize_t(b.first_node + b.n_nodes), 1);
      }, "slice of its rows in a per-node field: sim.displacement()[body.nodes]")
      .def_property_readonly("elements", [](const tissue::BodyRange& b) {
        return py::slice(py::ssize_t(b.first_element), py::ssize_t(b.first_element + b.n_elements), 1);
      }, "slice of its rows in a per-element field")
      .def("__repr__", [](const tissue::BodyRange& b) {
        return "<tissue.Body '" + b.name + "': nodes " + std::to_string(b.first_node) + ".." +
               std::to_string(b.first_node + b.n_nodes) + ", elements " + std::to_string(b.first_element) + ".." +
               std::to_string(b.first_element + b.n_elements) + ">";
      });
  py::class_<tissue::ToolResult>(m, "ToolResult", "One tool at the end of a tick")
      .def_property_readonly("tip", [](const tissue::ToolResult& t) { return numpy3(t.tip); })
      .def_property_readonly("axis", [](const tissue::ToolResult& t) { return numpy3(t.axis); })
      .def_property_readonly("force", [](const tissue::ToolResult& t) { return numpy3(t.force); },
                             "Force on the tool (N): what the hand feels")
      .def_readonly("contact_nodes", &tissue::ToolResult::contact_nodes)
      .def_readonly("grasped_nodes", &tissue::ToolResult::grasped_nodes)
      .def_readonly("grasp", &tissue::ToolResult::grasp, "The button held: a probe's grasp, a blade's cut")
      .def_readonly("cut", &tissue::ToolResult::cut, "A blade: the tissue gave, and was cut, after this tick");

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
}

/// tissue.Simulation: time, results, loads and fields.
void bind_simulation_steps(py::class_<PySimulation>& cls) {
  cls.def("step", [](PySimulation& s, py::handle ticks_arg, bool force) {
        const long ticks = tick_count(ticks_arg);
        check_work(ticks, double(s.value.steps_per_tick()) * double(s.value.n_elements()),
                   std::to_string(s.value.steps_per_tick()) + " TLED steps x " + std::to_string(s.value.n_elements()) +
                       " elements",
                   force);
        return locked(s, [&](Simulation& x) { return interruptible(ticks, [&](long n) { return x.step(n); }); });
      }, py::arg("ticks") = 1, py::kw_only(), py::arg("force") = false,
           "Run haptic ticks; returns the last one's TickResult. Ctrl-C stops it at a tick boundary "
           "(KeyboardInterrupt); more than 1e12 element updates need force=True")
      .def_property_readonly("last", [](PySimulation& s) { return locked(s, [](Simulation& x) { return x.last(); }); })
      .def("force", [](PySimulation& s, int tool) {
        return numpy3(locked(s, [&](Simulation& x) { return x.force(tool); }));
      }, py::arg("tool") = 0, "Force on the tool after the last tick (N)")
      .def("reset", [](PySimulation& s) { locked(s, [](Simulation& x) { x.reset(); }); },
           "Back to rest (u = 0, tick 0); keeps the loads")
      .def(
          "set_loads",
          [](PySimulation& s, py::handle nodes, py::array_t<double, py::array::c_style | py::array::forcecast> forces) {
            const std::vector<std::int32_t> ids = node_ids(nodes, 1, "nodes");
            if (forces.size() != 3 * py::ssize_t(ids.size()))
              throw std::invalid_argument("set_loads: forces must hold 3 values (x y z, N) per node: " +
                                          std::to_string(forces.size()) + " values for " +
                                          std::to_string(ids.size()) + " nodes");
            const std::span<const double> f(forces.data(), std::size_t(forces.size()));
            locked(s, [&](Simulation& x) { x.set_loads(ids, f); });
          },
          py::arg("nodes"), py::arg("forces"),
          "Constant external forces (N) from the next tick on: nodes (n,), forces (n, 3); replaces the scene's "
          "loads; empty arrays remove them")
      .def("dissipated_energy", [](PySimulation& s) {
        return locked(s, [](Simulation& x) { return x.dissipated_energy(); });
      }, "J dissipated by the viscoelastic (Prony) terms since the start")
      .def("viscous_stored_energy", [](PySimulation& s) {
        return locked(s, [](Simulation& x) { return x.viscous_stored_energy(); });
      }, "J stored in the Prony terms' branches after the last tick")
      .def("take_notes", [](PySimulation& s) { return locked(s, [](Simulation& x) { return x.take_notes(); }); })
      .def("positions_f32", [](PySimulation& s) {
        if (s.value.positions_on_device())
          throw std::invalid_argument("positions_f32: the " + s.value.backend() +
                                      " backend writes positions to device memory; use positions()");
        py::array_t<float> a({py::ssize_t(s.value.n_nodes()), py::ssize_t(3)});
        float* out = a.mutable_data();
        locked(s, [&](Simulation& x) { x.write_positions(out); });
        return a;
      }, "(n_nodes, 3) float32 deformed positions written straight from the store (host backends)")
      .def("__repr__", [](PySimulation& s) {
        return "<tissue.Simulation " + s.value.name() + ": " + std::to_string(s.value.n_nodes()) + " nodes, " +
               std::to_string(s.value.n_elements()) + " tets on " + s.value.backend() + " (" + s.value.precision() + ")>";
      });
}

/// tissue.Simulation: loading, sizes, the reference mesh and the tools.
void bind_simulation(py::module_& m) {
  auto cls = py::class_<PySimulation>(m, "Simulation", "A scene running on a backend, driven tick by tick")
      .def_static("load", [](const std::string& scene, std::optional<std::string> backend,
                             std::optional<std::string> precision, std::optional<std::string> depth) {
        py::gil_scoped_release free;
        return std::unique_ptr<PySimulation>(
            new PySimulation{Simulation::load(scene, options(backend, precision, depth)), {}});
      }, py::arg("scene"), py::arg("backend") = py::none(), py::arg("precision") = py::none(),
                  py::arg("depth") = py::none(), "Load a scene file or '@kidney'")
      .def_static("from_mesh", [](py::handle nodes, py::handle tets, double E, double nu, double rho, py::handle fixed,
                                  std::vector<double> tool_radii, double tool_shaft, std::optional<std::string> backend,
                                  std::optional<std::string> precision, std::optional<std::string> depth,
                                  std::string name) {
        tissue::MeshScene s;
        s.name = std::move(name);
        s.nodes = flat<double>(nodes, 3, "nodes");
        s.tets = node_ids(tets, 4, "tets");
        s.youngs_modulus = E;
        s.poisson_ratio = nu;
        s.density = rho;
        if (!fixed.is_none()) s.fixed_nodes = node_ids(fixed, 1, "fixed");
        s.tool_radii = std::move(tool_radii);
        s.tool_shaft = tool_shaft;
        py::gil_scoped_release free;
        return std::unique_ptr<PySimulation>(
            new PySimulation{Simulation::from_mesh(s, options(backend, precision, depth)), {}});
      }, py::arg("nodes"), py::arg("tets"), py::kw_only(), py::arg("E") = 3000.0, py::arg("nu") = 0.45,
                  py::arg("rho") = 1000.0, py::arg("fixed") = py::none(),
                  py::arg("tool_radii") = std::vector<double>{2e-3}, py::arg("tool_shaft") = 0.0,
                  py::arg("backend") = py::none(), py::arg("precision") = py::none(), py::arg("depth") = py::none(),
                  py::arg("name") = "<mesh>", "Build a simulation of a tetrahedral mesh with one material")
      .def_property_readonly("name", [](PySimulation& s) { return locked(s, [](Simulation& x) { return x.name(); }); })
      .def_property_readonly("backend", [](PySimulation& s) { return s.value.backend(); })
      .def_property_readonly("precision", [](PySimulation& s) { return s.value.precision(); })
      .def_property_readonly("device_name", [](PySimulation& s) { return s.value.device_name(); })
      .def_property_readonly("n_nodes", [](PySimulation& s) { return locked(s, [](Simulation& x) { return x.n_nodes(); }); })
      .def_property_readonly("n_elements", [](PySimulation& s) { return locked(s, [](Simulation& x) { return x.n_elements(); }); })
      .def_property_readonly("n_tools", [](PySimulation& s) { return s.value.n_tools(); })
      .def_property_readonly("tick_seconds", [](PySimulation& s) { return s.value.tick_seconds(); })
      .def_property_readonly("steps_per_tick", [](PySimulation& s) { return locked(s, [](Simulation& x) { return x.steps_per_tick(); }); })
      .def_property_readonly("dt", [](PySimulation& s) { return locked(s, [](Simulation& x) { return x.dt(); }); })
      .def_property_readonly("warnings", [](PySimulation& s) { return locked(s, [](Simulation& x) { return x.warnings(); }); })
      .def_property_readonly("bodies", [](PySimulation& s) { return locked(s, [](Simulation& x) { return x.bodies(); }); },
                             "the scene's bodies (tissue.Body), scene order; a scene of one mesh is one body")
      .def("body_contacts", [](PySimulation& s) {
        return body_contact_arrays(locked(s, [](Simulation& x) { return x.body_contacts(); }));
      }, kBodyContactsDoc)
      .def_property_readonly("ticks",
                             [](PySimulation& s) { return locked(s, [](Simulation& x) { return x.ticks(); }); })
      .def_property_readonly("time", [](PySimulation& s) { return locked(s, [](Simulation& x) { return x.time(); }); })
      .def_property_readonly("rest_positions", [](PySimulation& s) { return mesh_arrays(s).rest; },
                             "(n_nodes, 3) reference positions (m), read-only; a cut or a reset after one gives new "
                             "arrays (those handed out before keep the mesh they had)")
      .def_property_readonly("tetrahedra", [](PySimulation& s) { return mesh_arrays(s).tets; },
                             "(n_elements, 4) node ids, read-only (as rest_positions)")
      .def_property_readonly("surface_triangles", [](PySimulation& s) { return mesh_arrays(s).tris; },
                             "(n_triangles, 3) outward surface triangles, read-only (as rest_positions)")
      .def_property_readonly("mesh_version", [](PySimulation& s) {
        return locked(s, [](Simulation& x) { return x.mesh_version(); });
      }, "Counts the mesh's changes: 1 after loading, one more with each cut() and each reset() after one")
      .def("cut", [](PySimulation& s, py::handle origin, py::handle edge, py::handle sweep, const std::string& method) {
        const tissue::Vector3 o = vector3(origin, "origin"), e = vector3(edge, "edge"), w = vector3(sweep, "sweep");
        return locked(s, [&](Simulation& x) { return x.cut(o, e, w, method); });
      }, py::arg("origin"), py::arg("edge"), py::arg("sweep"), py::arg("method") = "snap-split",
           "Cut the tissue where it is now along the parallelogram origin + s edge + t sweep (m, the deformed "
           "configuration) and run on with the cut mesh: the motion, time, tools and loads carry over; the "
           "Prony history and grasps are dropped; reset() goes back to the mesh before the first cut "
           "(docs/cutting.md). Returns a CutStats")
      .def("set_tool_pose", [](PySimulation& s, int tool, py::handle tip, py::handle axis) {
        const tissue::Vector3 t = vector3(tip, "tip");
        const tissue::Vector3 a = axis.is_none() ? tissue::Vector3{0, 0, 0} : vector3(axis, "axis");
        locked(s, [&](Simulation& x) { x.set_tool_pose(tool, t, a); });
      }, py::arg("tool"), py::arg("tip"), py::arg("axis") = py::none(),
           "The pose the tool reaches at the end of the next tick (m); the host drives the tool from now on")
      .def("set_grasp", [](PySimulation& s, int tool, bool down) {
        locked(s, [&](Simulation& x) { x.set_grasp(tool, down); });
      }, py::arg("tool"), py::arg("down"))
      .def("follow_scene_path", [](PySimulation& s, int tool) {
        locked(s, [&](Simulation& x) { x.follow_scene_path(tool); });
      }, py::arg("tool"))
      .def("tool_radius", [](PySimulation& s, int tool) { return locked(s, [&](Simulation& x) { return x.tool_radius(tool); }); }, py::arg("tool"))
      .def("tool_shaft", [](PySimulation& s, int tool) { return locked(s, [&](Simulation& x) { return x.tool_shaft(tool); }); }, py::arg("tool"))
      .def("tool_friction", [](PySimulation& s, int tool) { return locked(s, [&](Simulation& x) { return x.tool_friction(tool); }); }, py::arg("tool"),
           "The tool's Coulomb friction coefficient mu (0 = frictionless)")
      .def("set_tool_friction", [](PySimulation& s, int tool, double mu) {
        locked(s, [&](Simulation& x) { x.set_tool_friction(tool, mu); });
      }, py::arg("tool"), py::arg("mu"),
           "The tool's Coulomb friction coefficient from the next tick on (finite, >= 0), contacts kept");
  bind_simulation_steps(cls);
  bind_simulation_fields(cls);
}

// ---- device arrays: __cuda_array_interface__ (version 3) and DLPack ----

/// DLPack's ABI (dlpack.h, version 0.8): the structs a consumer reads
/// from the "dltensor" capsule.
struct DLDevice {
  std::int32_t device_type;  ///< 2: CUDA
  std::int32_t device_id;
};
struct DLDataType {
  std::uint8_t code;  ///< 2: float
  std::uint8_t bits;
  std::uint16_t lanes;
};
struct DLTensor {
  void* data;
  DLDevice device;
  std::int32_t ndim;
  DLDataType dtype;
  std::int64_t* shape;
  std::int64_t* strides;  ///< in elements
  std::uint64_t byte_offset;
};
struct DLManagedTensor {
  DLTensor dl_tensor;
  void* manager_ctx;
  void (*deleter)(DLManagedTensor*);
};

/// A batch's field where it lies on the GPU (tissue.DeviceArray): no copy.
/// It keeps the batch alive; its memory holds the field until the batch's
/// next step, reset, set_material or set_loads.
struct PyDeviceArray {
  tissue::Batch::DeviceView view;
  py::object owner;
};

/// What a DLPack capsule owns: the shape and strides it points to, and the batch.
struct DLPackHold {
  DLManagedTensor tensor;
  std::vector<std::int64_t> shape, strides;
  py::object owner;
};

void dlpack_delete(DLManagedTensor* t) {
  PyGILState_STATE gil = PyGILState_Ensure();  // (a consumer may free its tensor without the GIL)
  delete static_cast<DLPackHold*>(t->manager_ctx);
  PyGILState_Release(gil);
}

py::capsule dlpack_capsule(const PyDeviceArray& a) {
  auto* hold = new DLPackHold{};
  hold->shape = a.view.shape;
  for (std::int64_t b : a.view.strides) hold->strides.push_back(b / a.view.scalar_bytes);
  hold->owner = a.owner;
  DLTensor& t = hold->tensor.dl_tensor;
  t.data = reinterpret_cast<void*>(a.view.data);
  t.device = {2, a.view.device};
  t.ndim = std::int32_t(hold->shape.size());
  t.dtype = {2, std::uint8_t(8 * a.view.scalar_bytes), 1};
  t.shape = hold->shape.data();
  t.strides = hold->strides.data();
  t.byte_offset = 0;
  hold->tensor.manager_ctx = hold;
  hold->tensor.deleter = dlpack_delete;
  // a capsule no consumer took (still named "dltensor") frees its tensor itself
  return py::capsule(&hold->tensor, "dltensor", [](PyObject* cap) {
    if (PyCapsule_IsValid(cap, "dltensor")) {
      auto* m = static_cast<DLManagedTensor*>(PyCapsule_GetPointer(cap, "dltensor"));
      if (m && m->deleter) m->deleter(m);
    } else {
      PyErr_Clear();
    }
  });
}

void bind_device_array(py::module_& m) {
  py::class_<PyDeviceArray>(m, "DeviceArray",
                            "A batch's field where it lies on the GPU, for PyTorch, CuPy or any DLPack reader without a copy "
                            "(__cuda_array_interface__, DLPack). Valid until the batch's next step, reset, "
                            "set_material or set_loads: read or copy it before then")
      .def_property_readonly("shape", [](const PyDeviceArray& a) { return py::tuple(py::cast(a.view.shape)); })
      .def_property_readonly("strides", [](const PyDeviceArray& a) { return py::tuple(py::cast(a.view.strides)); },
                             "bytes per step of each dimension")
      .def_property_readonly("dtype", [](const PyDeviceArray& a) { return a.view.scalar_bytes == 4 ? "float32" : "float64"; })
      .def_property_readonly("__cuda_array_interface__", [](const PyDeviceArray& a) {
        py::dict d;
        d["shape"] = py::tuple(py::cast(a.view.shape));
        d["typestr"] = a.view.scalar_bytes == 4 ? "<f4" : "<f8";
        // (not marked read-only: PyTorch refuses the flag; writing would change the simulation)
        d["data"] = py::make_tuple(a.view.data, false);
        d["strides"] = py::tuple(py::cast(a.view.strides));
        d["version"] = 3;
        return d;
      })
      .def("__dlpack__", [](const PyDeviceArray& a, py::object /*stream*/) { return dlpack_capsule(a); },
           py::arg("stream") = py::none(), "The field as a DLPack capsule (the engine's work is done when step() returns)")
      .def("__dlpack_device__", [](const PyDeviceArray& a) { return py::make_tuple(2, a.view.device); })
      .def("__repr__", [](const PyDeviceArray& a) {
        std::string shape;
        for (std::int64_t v : a.view.shape) shape += (shape.empty() ? "" : ", ") + std::to_string(v);
        return "<tissue.DeviceArray (" + shape + ") " + (a.view.scalar_bytes == 4 ? "float32" : "float64") +
               " on cuda:" + std::to_string(a.view.device) + ">";
      });
}

/// A batch's field on the device, every scene's or one's.
PyDeviceArray device_array(py::object self, std::optional<int> scene, Field f) {
  PyBatch& b = self.cast<PyBatch&>();
  tissue::Batch::DeviceView v =
      locked(b, [&](tissue::Batch& x) { return scene ? x.device_field(*scene, f) : x.device_field(f); });
  return {std::move(v), self};
}

/// The CUDA pointer, value count and scalar size of a __cuda_array_interface__
/// array of `shape`, C-contiguous float32 or float64; throws naming `what`.
std::tuple<std::uintptr_t, std::size_t, bool> cuda_array(py::handle h, const std::vector<py::ssize_t>& shape,
                                                          const std::string& what) {
  const py::dict cai = h.attr("__cuda_array_interface__").cast<py::dict>();
  const auto got = cai["shape"].cast<std::vector<py::ssize_t>>();
  const std::string type = cai["typestr"].cast<std::string>();
  std::string want;
  for (py::ssize_t v : shape) want += (want.empty() ? "" : ", ") + std::to_string(v);
  if (got != shape)
    throw std::invalid_argument(what + ": the device array must have shape (" + want + ") (scenes, tools, xyz)");
  if (type != "<f8" && type != "<f4")
    throw std::invalid_argument(what + ": the device array's type is " + type + "; it must be float64 or float32");
  const std::size_t scalar = type == "<f8" ? 8 : 4;
  if (cai.contains("strides") && !cai["strides"].is_none()) {
    const auto strides = cai["strides"].cast<std::vector<py::ssize_t>>();
    py::ssize_t expect = py::ssize_t(scalar);
    for (std::size_t k = shape.size(); k-- > 0;) {
      if (strides[k] != expect)
        throw std::invalid_argument(what + ": the device array must be C-contiguous (call .contiguous())");
      expect *= shape[k];
    }
  }
  std::size_t count = 1;
  for (py::ssize_t v : shape) count *= std::size_t(v);
  return {cai["data"].cast<py::tuple>()[0].cast<std::uintptr_t>(), count, scalar == 4};
}

/// (N, max_tools, 3): one vector per tool after the last tick, as `read` (Batch::read_forces, read_tips) gives it.
py::array_t<double> tool_array(PyBatch& b, void (tissue::Batch::*read)(std::span<double>) const) {
  py::array_t<double> a({py::ssize_t(b.value.size()), py::ssize_t(b.value.max_tools()), py::ssize_t(3)});
  double* out = a.mutable_data();
  const std::size_t size = std::size_t(a.size());
  locked(b, [&](tissue::Batch& x) { (x.*read)({out, size}); });
  return a;
}

/// tissue.Batch: time, failures, resets and arrays.
void bind_batch_steps(py::class_<PyBatch>& cls) {
  cls.def("step", [](PyBatch& b, py::handle ticks_arg, bool force) {
        const long ticks = tick_count(ticks_arg);
        double per_tick = 0;  // every scene's steps x elements
        for (int i = 0; i < int(b.value.size()); ++i)
          per_tick += double(b.value.steps_per_tick(i)) * double(b.value.n_elements(i));
        check_work(ticks, per_tick, std::to_string(b.value.size()) + " scenes' TLED steps x elements", force);
        return locked(b, [&](tissue::Batch& x) { return interruptible(ticks, [&](long n) { return x.step(n); }); });
      }, py::arg("ticks") = 1, py::kw_only(), py::arg("force") = false,
           "Run haptic ticks of every running scene; returns how many still run. Ctrl-C stops it at a tick boundary "
           "(KeyboardInterrupt); more than 1e12 element updates in all need force=True")
      .def("failed", [](PyBatch& b, int scene) { return locked(b, [&](tissue::Batch& x) { return x.failed(scene); }); },
           py::arg("scene"))
      .def("failure", [](PyBatch& b, int scene) { return locked(b, [&](tissue::Batch& x) { return x.failure(scene); }); },
           py::arg("scene"), "Why the scene stopped ('' while it runs)")
      .def_property_readonly("failed_scenes",
                             [](PyBatch& b) { return locked(b, [&](tissue::Batch& x) { return x.failed_scenes(); }); })
      .def("last", [](PyBatch& b, int scene) { return locked(b, [&](tissue::Batch& x) { return x.last(scene); }); },
           py::arg("scene"), "The scene's last TickResult (its last good one when it failed)")
      .def("ticks", [](PyBatch& b, int scene) { return locked(b, [&](tissue::Batch& x) { return x.ticks(scene); }); },
           py::arg("scene"))
      .def("reset", [](PyBatch& b, std::optional<int> scene) {
        locked(b, [&](tissue::Batch& x) {
          if (scene)
            x.reset(*scene);
          else
            x.reset();
        });
      }, py::arg("scene") = py::none(), "One scene (or every scene) back to rest")
      .def("take_notes", [](PyBatch& b, int scene) { return locked(b, [&](tissue::Batch& x) { return x.take_notes(scene); }); },
           py::arg("scene"))
      .def("forces", [](PyBatch& b) { return tool_array(b, &tissue::Batch::read_forces); },
           "(N, max_tools, 3) forces on the tools after the last tick (N)")
      .def("tips", [](PyBatch& b) { return tool_array(b, &tissue::Batch::read_tips); },
           "(N, max_tools, 3) the tools' tips after the last tick (m)")
      .def("device_displacement",
           [](py::object self, std::optional<int> s) { return device_array(self, s, Field::Displacement); },
           py::arg("scene") = py::none(),
           "(N, nodes, 3) m where it lies on the GPU (a DeviceArray: torch.as_tensor(a, device='cuda'), "
           "torch.from_dlpack(a), cupy.asarray(a)); valid until the next step")
      .def("device_internal_force",
           [](py::object self, std::optional<int> s) { return device_array(self, s, Field::InternalForce); },
           py::arg("scene") = py::none(), "(N, nodes, 3) N where it lies on the GPU; valid until the next step")
      .def("__repr__", [](PyBatch& b) {
        return "<tissue.Batch " + std::to_string(b.value.size()) + " scenes on " + b.value.backend() + " (" +
               b.value.precision() + ")>";
      });
}

/// {term: (g, tau)} (1-based terms; None keeps a value) as Prony changes; throws naming the entry.
std::vector<tissue::PronyChange> prony_changes(py::handle h) {
  if (!py::isinstance<py::dict>(h))
    throw std::invalid_argument("MaterialChange: prony must be a dict {term: (g, tau)} with 1-based terms");
  std::vector<tissue::PronyChange> out;
  for (auto [k, v] : h.cast<py::dict>()) {
    if (!py::isinstance<py::int_>(k) || py::isinstance<py::bool_>(k))
      throw std::invalid_argument("MaterialChange: prony term " + py::repr(k).cast<std::string>() +
                                  " must be a whole number (1-based)");
    const py::tuple pair = py::reinterpret_borrow<py::object>(v).cast<py::tuple>();
    if (pair.size() != 2)
      throw std::invalid_argument("MaterialChange: prony term " + py::repr(k).cast<std::string>() +
                                  " must map to a pair (g, tau)");
    out.push_back({k.cast<int>(), pair[0].cast<std::optional<double>>(), pair[1].cast<std::optional<double>>()});
  }
  std::sort(out.begin(), out.end(), [](const auto& a, const auto& b) { return a.term < b.term; });
  return out;
}

/// tissue.MaterialChange: a batch scene's new material parameters.
void bind_material_change(py::module_& m) {
  py::class_<tissue::MaterialChange>(m, "MaterialChange", "New parameters for one material of a scene (None keeps it)")
      .def(py::init([](std::string material, std::optional<double> E, std::optional<double> nu,
                       std::optional<double> rho, std::optional<double> fibre_stiffness, py::handle prony) {
             tissue::MaterialChange c{std::move(material), E, nu, rho, fibre_stiffness, {}};
             if (!prony.is_none()) c.prony = prony_changes(prony);
             return c;
           }),
           py::arg("material") = "", py::kw_only(), py::arg("E") = py::none(), py::arg("nu") = py::none(),
           py::arg("rho") = py::none(), py::arg("fibre_stiffness") = py::none(), py::arg("prony") = py::none(),
           "prony: {term: (g, tau)} with 1-based terms, None in a pair keeping that value")
      .def_readwrite("material", &tissue::MaterialChange::material)
      .def_readwrite("E", &tissue::MaterialChange::youngs_modulus)
      .def_readwrite("nu", &tissue::MaterialChange::poisson_ratio)
      .def_readwrite("rho", &tissue::MaterialChange::density)
      .def_readwrite("fibre_stiffness", &tissue::MaterialChange::fibre_stiffness)
      .def_property_readonly("prony", [](const tissue::MaterialChange& c) {
        py::dict d;
        for (const tissue::PronyChange& p : c.prony) d[py::int_(p.term)] = py::make_tuple(p.g, p.tau);
        return d;
      });
}

/// tissue.Batch: loading, sizes, materials and the tools.
void bind_batch(py::module_& m) {
  auto cls = py::class_<PyBatch>(m, "Batch", "Many scenes stepped together on one backend (docs/batch.md)")
      .def(py::init([](py::object scenes, std::optional<int> copies, std::optional<std::string> backend,
                       std::optional<std::string> precision, std::optional<std::string> depth) {
             std::vector<tissue::BatchScene> list;
             if (py::isinstance<py::str>(scenes)) {
               const int n = copies.value_or(1);
               if (n < 1) throw std::invalid_argument("Batch: copies = " + std::to_string(n) + " must be >= 1");
               // the facade's copies: a count beyond the host's memory is refused before a list is made
               const std::string name = scenes.cast<std::string>();
               const tissue::SimulationOptions o = options(backend, precision, depth);
               py::gil_scoped_release free;
               return std::unique_ptr<PyBatch>(new PyBatch{tissue::Batch::load(name, n, o), {}});
             } else {
               if (copies) throw std::invalid_argument("Batch: copies applies to one scene name, not to a list");
               for (py::handle item : scenes) {
                 if (py::isinstance<py::str>(item)) {
                   list.push_back({item.cast<std::string>(), {}, {}});
                 } else {
                   const auto pair = item.cast<py::tuple>();
                   if (pair.size() != 2)
                     throw std::invalid_argument("Batch: a scene is a name or (name, [MaterialChange, ...])");
                   list.push_back({pair[0].cast<std::string>(), pair[1].cast<std::vector<tissue::MaterialChange>>(), {}});
                 }
               }
             }
             py::gil_scoped_release free;
             return std::unique_ptr<PyBatch>(new PyBatch{tissue::Batch::load(list, options(backend, precision, depth)), {}});
           }),
           py::arg("scenes"), py::arg("copies") = py::none(), py::kw_only(), py::arg("backend") = py::none(),
           py::arg("precision") = py::none(), py::arg("depth") = py::none(),
           "Batch('@kidney', 64) or Batch(['a.xml', ('b.xml', [MaterialChange('tissue', E=5000)])])")
      .def("__len__", [](PyBatch& b) { return b.value.size(); })
      .def_property_readonly("size", [](PyBatch& b) { return b.value.size(); })
      .def_property_readonly("backend", [](PyBatch& b) { return b.value.backend(); })
      .def_property_readonly("precision", [](PyBatch& b) { return b.value.precision(); })
      .def_property_readonly("device_name", [](PyBatch& b) { return b.value.device_name(); })
      .def_property_readonly("max_tools", [](PyBatch& b) { return b.value.max_tools(); })
      .def_property_readonly("distinct_models", [](PyBatch& b) { return b.value.distinct_models(); })
      .def_property_readonly("groups", [](PyBatch& b) { return b.value.groups(); },
                             "groups of scenes stepped as one launch per pass (cuda; docs/batch.md)")
      .def_property_readonly("ticks_together", [](PyBatch& b) { return b.value.ticks_together(); },
                             "scene ticks run in a group so far")
      .def_property_readonly("scene_host_bytes", [](PyBatch& b) { return b.value.scene_host_bytes(); })
      .def_property_readonly("scene_device_bytes", [](PyBatch& b) { return b.value.scene_device_bytes(); })
      .def("name", [](PyBatch& b, int scene) { return b.value.name(scene); }, py::arg("scene"))
      .def("n_nodes", [](PyBatch& b, int scene) { return b.value.n_nodes(scene); }, py::arg("scene"))
      .def("n_elements", [](PyBatch& b, int scene) { return b.value.n_elements(scene); }, py::arg("scene"))
      .def("n_tools", [](PyBatch& b, int scene) { return b.value.n_tools(scene); }, py::arg("scene"))
      .def("steps_per_tick", [](PyBatch& b, int scene) { return b.value.steps_per_tick(scene); }, py::arg("scene"))
      .def("dt", [](PyBatch& b, int scene) { return b.value.dt(scene); }, py::arg("scene"))
      .def("tick_seconds", [](PyBatch& b, int scene) { return b.value.tick_seconds(scene); }, py::arg("scene"))
      .def("path_end", [](PyBatch& b, int scene) { return b.value.path_end(scene); }, py::arg("scene"),
           "When the scene's scripted tool paths end (s); 0 without paths")
      .def("warnings", [](PyBatch& b, int scene) { return locked(b, [&](tissue::Batch& x) { return x.warnings(scene); }); },
           py::arg("scene"))
      .def("bodies", [](PyBatch& b, int scene) { return b.value.bodies(scene); }, py::arg("scene"),
           "the scene's bodies (tissue.Body)")
      .def("body_contacts", [](PyBatch& b, int scene) {
        return body_contact_arrays(locked(b, [&](tissue::Batch& x) { return x.body_contacts(scene); }));
      }, py::arg("scene"), "One scene's body contacts (Simulation.body_contacts)")
      .def("set_material", [](PyBatch& b, int scene, std::string material, std::optional<double> E,
                              std::optional<double> nu, std::optional<double> rho) {
        locked(b, [&](tissue::Batch& x) { x.set_material(scene, {material, E, nu, rho}); });
      }, py::arg("scene"), py::arg("material") = "", py::kw_only(), py::arg("E") = py::none(),
           py::arg("nu") = py::none(), py::arg("rho") = py::none(),
           "New E, nu or rho for a scene's material ('' = all); that scene starts again at rest")
      .def("set_tool_pose", [](PyBatch& b, int scene, int tool, py::handle tip, py::handle axis) {
        const tissue::Vector3 t = vector3(tip, "tip");
        const tissue::Vector3 a = axis.is_none() ? tissue::Vector3{0, 0, 0} : vector3(axis, "axis");
        locked(b, [&](tissue::Batch& x) { x.set_tool_pose(scene, tool, t, a); });
      }, py::arg("scene"), py::arg("tool"), py::arg("tip"), py::arg("axis") = py::none())
      .def("tool_friction", [](PyBatch& b, int scene, int tool) { return b.value.tool_friction(scene, tool); },
           py::arg("scene"), py::arg("tool"))
      .def("set_tool_friction", [](PyBatch& b, int scene, int tool, double mu) {
        locked(b, [&](tissue::Batch& x) { x.set_tool_friction(scene, tool, mu); });
      }, py::arg("scene"), py::arg("tool"), py::arg("mu"),
           "One scene's tool's Coulomb friction coefficient from its next tick on")
      .def("set_tool_poses", [](PyBatch& b, py::handle tips, py::handle axes) {
        const std::size_t n = b.value.size(), t = std::size_t(b.value.max_tools());
        if (py::hasattr(tips, "__cuda_array_interface__") && axes.is_none()) {  // a device array: one copy
          const auto [ptr, count, single] =
              cuda_array(tips, {py::ssize_t(n), py::ssize_t(t), 3}, "set_tool_poses: tips");
          locked(b, [&, ptr = ptr, count = count, single = single](tissue::Batch& x) {
            x.set_tool_poses_from_device(ptr, count, single);
          });
          return;
        }
        auto take = [&](py::handle h, const char* what) {
          const auto a = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(h);
          if (!a || a.ndim() != 3 || std::size_t(a.shape(0)) != n || std::size_t(a.shape(1)) != t || a.shape(2) != 3)
            throw std::invalid_argument(std::string("set_tool_poses: ") + what + " must have shape (" +
                                        std::to_string(n) + ", " + std::to_string(t) + ", 3) (scenes, tools, xyz)");
          return std::vector<double>(a.data(), a.data() + a.size());
        };
        const std::vector<double> tv = take(tips, "tips");
        const std::vector<double> av = axes.is_none() ? std::vector<double>{} : take(axes, "axes");
        locked(b, [&](tissue::Batch& x) { x.set_tool_poses(tv, av); });
      }, py::arg("tips"), py::arg("axes") = py::none(),
           "Every scene's tool poses from (N, max_tools, 3) arrays (m), NumPy or a CUDA device array "
           "(__cuda_array_interface__: PyTorch, CuPy); rows past a scene's tools are ignored")
      .def("set_grasp", [](PyBatch& b, int scene, int tool, bool down) {
        locked(b, [&](tissue::Batch& x) { x.set_grasp(scene, tool, down); });
      }, py::arg("scene"), py::arg("tool"), py::arg("down"))
      .def("follow_scene_path", [](PyBatch& b, int scene, int tool) {
        locked(b, [&](tissue::Batch& x) { x.follow_scene_path(scene, tool); });
      }, py::arg("scene"), py::arg("tool"))
      .def("set_tool_path", [](PyBatch& b, int scene, int tool, py::handle rows) {
        const auto a = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(rows);
        if (!a || a.ndim() != 2 || (a.shape(1) != 4 && a.shape(1) != 5 && a.shape(1) != 8))
          throw std::invalid_argument("set_tool_path: rows must have shape (n, 4), (n, 5) or (n, 8): t x y z "
                                      "[grasp [ax ay az]]");
        std::vector<tissue::PathPoint> path;
        for (py::ssize_t i = 0; i < a.shape(0); ++i) {
          tissue::PathPoint p;
          p.t = a.at(i, 0);
          p.tip = {a.at(i, 1), a.at(i, 2), a.at(i, 3)};
          if (a.shape(1) >= 5) p.grasp = a.at(i, 4) != 0;
          if (a.shape(1) == 8) p.axis = {a.at(i, 5), a.at(i, 6), a.at(i, 7)};
          path.push_back(p);
        }
        locked(b, [&](tissue::Batch& x) { x.set_tool_path(scene, tool, path); });
      }, py::arg("scene"), py::arg("tool"), py::arg("rows"), "A scripted path for one tool: rows t x y z [grasp [ax ay az]]")
      .def("set_loads", [](PyBatch& b, int scene, py::handle nodes, py::handle forces) {
        const std::vector<std::int32_t> ids = node_ids(nodes, 1, "nodes");
        const std::vector<double> f = flat<double>(forces, 3, "forces");
        locked(b, [&](tissue::Batch& x) { x.set_loads(scene, ids, f); });
      }, py::arg("scene"), py::arg("nodes"), py::arg("forces"));
  bind_batch_steps(cls);
  bind_batch_fields(cls);
}

}  // namespace

PYBIND11_MODULE(_tissue, m) {
  bind_module(m);
  bind_results(m);
  bind_simulation(m);
  bind_material_change(m);
  bind_device_array(m);
  bind_batch(m);
}

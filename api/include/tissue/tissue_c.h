/* Tissue's C interface (docs/embedding.md): the Simulation facade of
 * tissue/simulation.hpp for hosts that are not C++ (C, Rust, C#, Python's
 * ctypes, game engines' plug-in layers).
 *
 * Conventions:
 * - Every function that can fail returns a tissue_status; TISSUE_OK is 0.
 *   On failure, tissue_last_error() gives the message (naming the file,
 *   element, node or value and the rule broken) for the calling thread,
 *   valid until that thread's next call into the library.
 * - No exception, abort or signal crosses this interface; out of memory is
 *   TISSUE_ERROR with a message.
 * - Units are SI (m, N, Pa, s). Vectors are 3 doubles x, y, z. Arrays of
 *   nodes are 3 values per node, interleaved.
 * - A tissue_simulation (or tissue_batch) is used from one thread at a time.
 */
#ifndef TISSUE_TISSUE_C_H
#define TISSUE_TISSUE_C_H

#include <stddef.h>
#include <stdint.h>

#include "tissue/fields.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef enum tissue_status {
  TISSUE_OK = 0,
  TISSUE_BAD_ARGUMENT = 1, /* a null pointer, an index out of range, a wrong size, a non-finite value */
  TISSUE_ERROR = 2,        /* a scene or mesh that does not validate, a backend that cannot run, out of memory */
  TISSUE_UNSTABLE = 3      /* the simulation went unstable (NaN or an inverted element); tissue_reset to go on */
} tissue_status;

/* TISSUE_FIELD_DISPLACEMENT = 0 (3 per node, m), TISSUE_FIELD_POSITION = 1
 * (3 per node, m), TISSUE_FIELD_PRESSURE = 2 (1 per node, Pa),
 * TISSUE_FIELD_INTERNAL_FORCE = 3 (3 per node, N), TISSUE_FIELD_JACOBIAN = 4
 * (1 per element): tissue/fields.h's list. */
typedef enum tissue_field {
#define TISSUE_FIELD_C_ENUM(c_name, cpp_name, python, per, components, unit, what) TISSUE_FIELD_##c_name,
  TISSUE_FIELD_LIST(TISSUE_FIELD_C_ENUM)
#undef TISSUE_FIELD_C_ENUM
  TISSUE_FIELD_COUNT
} tissue_field;

typedef struct tissue_simulation tissue_simulation;

/* A host's mesh (tissue::MeshScene): pointers are read during the call only. */
typedef struct tissue_mesh {
  const double* nodes;       /* 3 x n_nodes (m) */
  int32_t n_nodes;
  const int32_t* tets;       /* 4 x n_tets, 0-based node ids */
  int32_t n_tets;
  double youngs_modulus;     /* Pa */
  double poisson_ratio;
  double density;            /* kg/m^3 */
  const int32_t* fixed_nodes; /* may be NULL when n_fixed is 0 */
  int32_t n_fixed;
  double tool_radius;        /* one spherical tool (m) */
} tissue_mesh;

/* The message of this thread's last failure ("" after a success). */
const char* tissue_last_error(void);
/* "major.minor.patch". */
const char* tissue_version(void);

/* Opens a scene file or "@kidney". backend ("cpu", "cuda"), precision
 * ("float", "double") and depth ("all", "auto", "N") may be NULL or "" to
 * keep the scene's setting. */
tissue_status tissue_open_scene(const char* scene, const char* backend, const char* precision, const char* depth,
                                tissue_simulation** out);
tissue_status tissue_open_mesh(const tissue_mesh* mesh, const char* backend, const char* precision,
                               tissue_simulation** out);
/* Frees the simulation (NULL is ignored). */
void tissue_close(tissue_simulation* sim);

/* Sizes; 0 for a NULL simulation. */
size_t tissue_node_count(const tissue_simulation* sim);
size_t tissue_element_count(const tissue_simulation* sim);
int tissue_tool_count(const tissue_simulation* sim);
double tissue_tick_seconds(const tissue_simulation* sim);
/* The scene's bodies (docs/scene-format.md, "Bodies"; a scene of one mesh
 * is one body "body"): how many (0 for NULL); a body's name (valid while
 * sim lives; NULL for a bad index); and its ranges: its nodes are
 * first_node .. first_node + n_nodes - 1 of every per-node field, its
 * elements likewise. Any range pointer may be NULL. */
int tissue_body_count(const tissue_simulation* sim);
const char* tissue_body_name(const tissue_simulation* sim, int body);
tissue_status tissue_body_range(const tissue_simulation* sim, int body, size_t* first_node, size_t* n_nodes,
                                size_t* first_element, size_t* n_elements);
/* The surface nodes inside another body after the last tick
 * (tissue::Simulation::body_contacts; a scene's <contact bodies="a b">):
 * how many (0 before the first tick and for a scene without body contact),
 * and per contact, in ascending node id: the node; the other body's
 * surface triangle it was inside, as its 3 corner node ids (3 per contact);
 * the node's body and the triangle's (2 per contact, indices as in
 * tissue_body_range); and how far inside it was before the step's
 * correction (m, >= 0). capacity is the contacts the arrays hold (nodes and
 * depths capacity values, triangles 3 capacity, bodies 2 capacity); one
 * below the count is TISSUE_BAD_ARGUMENT naming both, with nothing written.
 * Any array pointer, and written, may be NULL; written receives the count. */
tissue_status tissue_body_contact_count(const tissue_simulation* sim, int32_t* count);
tissue_status tissue_body_contacts(const tissue_simulation* sim, int32_t* nodes, int32_t* triangles, int32_t* bodies,
                                   double* depths, size_t capacity, size_t* written);

/* The pose the tool reaches at the end of the next tick; axis may be NULL
 * (the scene's shaft direction). From the first call the host drives it. */
tissue_status tissue_set_tool_pose(tissue_simulation* sim, int tool, const double tip[3], const double axis[3]);
tissue_status tissue_set_grasp(tissue_simulation* sim, int tool, int down);
/* The tool's Coulomb friction coefficient (>= 0; 0 = frictionless) from
 * the next tick on; tissue_tool_friction reads it (NaN for a bad tool). */
tissue_status tissue_set_tool_friction(tissue_simulation* sim, int tool, double mu);
double tissue_tool_friction(const tissue_simulation* sim, int tool);
/* Constant external forces from the next tick on: x y z (N) per node of
 * nodes (count nodes, 3 count forces); replaces the scene's loads; count 0
 * removes every load (nodes and forces may then be NULL). */
tissue_status tissue_set_loads(tissue_simulation* sim, const int32_t* nodes, const double* forces, size_t count);
/* Runs ticks >= 1 haptic ticks. */
tissue_status tissue_step(tissue_simulation* sim, long ticks);
/* Back to rest (u = 0, tick 0), the mesh as it was before any cut. */
tissue_status tissue_reset(tissue_simulation* sim);
/* Cuts the tissue where it is now, between ticks, along the parallelogram
 * origin + s edge + t sweep, s, t in [0, 1] (m, the deformed configuration;
 * tissue::Simulation::cut, docs/cutting.md) and runs on with the cut mesh:
 * tissue_node_count and tissue_element_count change, the old nodes keep
 * their ids. method: "snap-split" (NULL or ""), "snap" or "split". A
 * refused cut (TISSUE_BAD_ARGUMENT, naming the rule) changes nothing. */
tissue_status tissue_cut(tissue_simulation* sim, const double origin[3], const double edge[3], const double sweep[3],
                         const char* method);
/* The force on the tool after the last tick (N): what the hand feels. */
tissue_status tissue_tool_force(const tissue_simulation* sim, int tool, double force[3]);
/* How many surface nodes touch the tool after the last tick. */
tissue_status tissue_tool_contact_count(const tissue_simulation* sim, int tool, int32_t* count);
/* Simulated time (s). */
double tissue_time(const tissue_simulation* sim);
/* Energy the viscoelastic (Prony) terms dissipated since the start (J); 0
 * for elastic materials or a NULL simulation. */
double tissue_dissipated_energy(const tissue_simulation* sim);
/* Copies a field into out, which holds exactly count values (components x
 * nodes, or elements for the Jacobian). */
tissue_status tissue_read_field(tissue_simulation* sim, tissue_field field, double* out, size_t count);

/* ---- A batch of scenes stepped together (tissue::Batch; docs/batch.md) ----
 * Scenes are numbered 0 .. tissue_batch_size() - 1. A scene that goes
 * unstable stops alone: tissue_batch_step still returns TISSUE_OK, and
 * tissue_batch_scene_failed / tissue_batch_failure say which and why. */
typedef struct tissue_batch tissue_batch;

/* Opens count scenes (files or "@kidney"; the same name may repeat) on one
 * backend and precision (NULL or "" = the first scene's). */
tissue_status tissue_batch_open(const char* const* scenes, size_t count, const char* backend, const char* precision,
                                const char* depth, tissue_batch** out);
/* Frees the batch (NULL is ignored). */
void tissue_batch_close(tissue_batch* batch);
/* Scenes in the batch, and the most tools any has; 0 for a NULL batch. */
size_t tissue_batch_size(const tissue_batch* batch);
int tissue_batch_max_tools(const tissue_batch* batch);
size_t tissue_batch_node_count(const tissue_batch* batch, int scene);
/* New (E, nu, rho) for a scene's material ("" or NULL = every material);
 * a value that is NaN keeps the scene's. The scene starts again at rest. */
tissue_status tissue_batch_set_material(tissue_batch* batch, int scene, const char* material, double youngs_modulus,
                                        double poisson_ratio, double density);
tissue_status tissue_batch_set_tool_pose(tissue_batch* batch, int scene, int tool, const double tip[3],
                                         const double axis[3]);
/* One scene's tool's Coulomb friction coefficient from its next tick on. */
tissue_status tissue_batch_set_tool_friction(tissue_batch* batch, int scene, int tool, double mu);
/* Every scene's tool tips (and axes, or NULL) at once: count = size x
 * max_tools x 3 values, row-major. */
tissue_status tissue_batch_set_tool_poses(tissue_batch* batch, const double* tips, const double* axes, size_t count);
tissue_status tissue_batch_set_grasp(tissue_batch* batch, int scene, int tool, int down);
/* ticks >= 1 haptic ticks of every running scene; running (may be NULL)
 * receives how many still run. */
tissue_status tissue_batch_step(tissue_batch* batch, long ticks, size_t* running);
/* *failed = 1 when the scene has stopped; tissue_batch_failure gives why
 * ("" while it runs; valid until the next call on the batch). */
tissue_status tissue_batch_scene_failed(const tissue_batch* batch, int scene, int* failed);
const char* tissue_batch_failure(tissue_batch* batch, int scene);
/* One scene (scene >= 0) or every scene (scene = -1) back to rest. */
tissue_status tissue_batch_reset(tissue_batch* batch, int scene);
/* Forces on every tool after the last tick: count = size x max_tools x 3. */
tissue_status tissue_batch_forces(const tissue_batch* batch, double* out, size_t count);
/* One scene's field (as tissue_read_field). */
tissue_status tissue_batch_read_field(tissue_batch* batch, int scene, tissue_field field, double* out, size_t count);

/* A field where the cuda backend keeps it, described for CUDA host code (no
 * copy; tissue::Batch::device_field, docs/batch.md "Device arrays"). */
typedef struct tissue_device_view {
  uintptr_t data;      /* a device pointer */
  int ndim;            /* 3: (scenes, nodes, 3); 2: one scene's (nodes, 3) */
  int64_t shape[3];
  int64_t strides[3];  /* bytes per step of each dimension */
  int scalar_bytes;    /* 4 (float) or 8 (double) */
  int device;          /* the CUDA device */
} tissue_device_view;
/* TISSUE_FIELD_DISPLACEMENT or TISSUE_FIELD_INTERNAL_FORCE of one scene
 * (scene >= 0) or of every scene (scene = -1: they must lie one stride
 * apart, scenes of one group). Valid until the next step, reset,
 * set_material or set_loads of the batch. TISSUE_BAD_ARGUMENT naming why
 * on the cpu backend, for another field or for scenes not one stride apart. */
tissue_status tissue_batch_device_field(tissue_batch* batch, int scene, tissue_field field, tissue_device_view* out);
/* Every scene's tool tips from a CUDA device array of count = size x
 * max_tools x 3 contiguous values, double (single = 0) or float: one copy to
 * the host, then as tissue_batch_set_tool_poses. */
tissue_status tissue_batch_set_tool_poses_from_device(tissue_batch* batch, uintptr_t tips, size_t count, int single);

#ifdef __cplusplus
}
#endif

#endif /* TISSUE_TISSUE_C_H */

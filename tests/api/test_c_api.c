/* The C interface (tissue/tissue_c.h) from a C program: a host's mesh,
 * a press, the force and a field, the body contacts of a scene of two
 * bodies, and every misuse answered by a status and a message (no crash).
 * Exit 0 when every check passes; each failure is printed. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "tissue/tissue_c.h"

static int failures = 0;

#define CHECK(cond)                                                  \
  do {                                                               \
    if (!(cond)) {                                                   \
      fprintf(stderr, "%s:%d: check failed: %s\n", __FILE__, __LINE__, #cond); \
      ++failures;                                                    \
    }                                                                \
  } while (0)

static int contains(const char* text, const char* part) { return strstr(text, part) != NULL; }

/* A 10 x 10 x 10 mm cube of 2 x 2 x 2 cells, 6 tets each (Kuhn split). */
enum { N = 2, NN = (N + 1) * (N + 1) * (N + 1), NT = 6 * N * N * N };
static int32_t id(int i, int j, int k) { return i + (N + 1) * (j + (N + 1) * k); }

static void cube(double* nodes, int32_t* tets) {
  for (int k = 0; k <= N; ++k)
    for (int j = 0; j <= N; ++j)
      for (int i = 0; i <= N; ++i) {
        double* p = nodes + 3 * id(i, j, k);
        p[0] = 0.005 * i, p[1] = 0.005 * j, p[2] = 0.005 * k;
      }
  /* The six tets around the diagonal 0-6 of a cell with corners c[0..7]. */
  static const int split[6][4] = {{0, 1, 2, 6}, {0, 2, 3, 6}, {0, 3, 7, 6}, {0, 7, 4, 6}, {0, 4, 5, 6}, {0, 5, 1, 6}};
  int t = 0;
  for (int k = 0; k < N; ++k)
    for (int j = 0; j < N; ++j)
      for (int i = 0; i < N; ++i) {
        const int32_t c[8] = {id(i, j, k),         id(i + 1, j, k),         id(i + 1, j + 1, k),     id(i, j + 1, k),
                              id(i, j, k + 1),     id(i + 1, j, k + 1),     id(i + 1, j + 1, k + 1), id(i, j + 1, k + 1)};
        for (int s = 0; s < 6; ++s, ++t)
          for (int a = 0; a < 4; ++a) tets[4 * t + a] = c[split[s][a]];
      }
}

/* A batch of two kidneys through the C interface on `backend`: stepping,
 * forces, fields, a material change, resets, the device view (cuda) or its
 * refusal (cpu), and misuse answered by a status and a message. */
static void batch_checks(const char* backend) {
  const char* scenes[2] = {"@kidney", "@kidney"};
  tissue_batch* b = NULL;
  const int cuda = strcmp(backend, "cuda") == 0;
  if (tissue_batch_open(scenes, 2, backend, "float", "all", &b) != TISSUE_OK) {
    CHECK(cuda); /* the cpu always opens */
    CHECK(b == NULL);
    if (cuda) printf("batch on cuda skipped: %s\n", tissue_last_error());
    return;
  }
  CHECK(tissue_batch_size(b) == 2 && tissue_batch_max_tools(b) == 1);
  const size_t nodes = tissue_batch_node_count(b, 0);
  CHECK(nodes > 1000 && tissue_batch_node_count(b, 1) == nodes);
  if (cuda) { /* the two copies form one group: their fields lie one slot apart */
    tissue_device_view all, one;
    CHECK(tissue_batch_device_field(b, -1, TISSUE_FIELD_DISPLACEMENT, &all) == TISSUE_OK);
    CHECK(all.ndim == 3 && all.shape[0] == 2 && all.shape[1] == (int64_t)nodes && all.shape[2] == 3);
    CHECK(all.scalar_bytes == 4 && all.data != 0 && all.strides[2] == 4);
    CHECK(tissue_batch_device_field(b, 1, TISSUE_FIELD_INTERNAL_FORCE, &one) == TISSUE_OK);
    CHECK(one.ndim == 2 && one.shape[0] == (int64_t)nodes && one.scalar_bytes == 4);
    CHECK(tissue_batch_device_field(b, 1, TISSUE_FIELD_DISPLACEMENT, &one) == TISSUE_OK);
    CHECK(one.data == all.data + (uintptr_t)all.strides[0]);
  } else {
    tissue_device_view v;
    CHECK(tissue_batch_device_field(b, -1, TISSUE_FIELD_DISPLACEMENT, &v) == TISSUE_BAD_ARGUMENT);
    CHECK(contains(tissue_last_error(), "host"));
  }
  tissue_device_view v;
  CHECK(tissue_batch_device_field(b, 0, TISSUE_FIELD_JACOBIAN, &v) == TISSUE_BAD_ARGUMENT);
  CHECK(tissue_batch_device_field(b, 0, (tissue_field)9, &v) == TISSUE_BAD_ARGUMENT);
  CHECK(tissue_batch_device_field(b, 0, TISSUE_FIELD_DISPLACEMENT, NULL) == TISSUE_BAD_ARGUMENT);
  CHECK(tissue_batch_set_tool_poses_from_device(b, 0, 5, 0) == TISSUE_BAD_ARGUMENT);
  CHECK(contains(tissue_last_error(), "holds 5 values"));

  size_t running = 0;
  CHECK(tissue_batch_step(b, 120, &running) == TISSUE_OK && running == 2); /* the probe presses after 100 */
  double f[6];
  CHECK(tissue_batch_forces(b, f, 6) == TISSUE_OK);
  const double f0 = sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2]);
  CHECK(f0 > 0);
  CHECK(f[0] == f[3] && f[1] == f[4] && f[2] == f[5]); /* two copies of one scene */
  CHECK(tissue_batch_forces(b, f, 5) == TISSUE_BAD_ARGUMENT && contains(tissue_last_error(), "holds 5 values"));
  double* u = (double*)malloc(3 * nodes * sizeof(double));
  CHECK(u != NULL);
  CHECK(tissue_batch_read_field(b, 1, TISSUE_FIELD_DISPLACEMENT, u, 3 * nodes) == TISSUE_OK);
  double umax = 0;
  for (size_t k = 0; k < 3 * nodes; ++k) umax = fmax(umax, fabs(u[k]));
  CHECK(umax > 1e-4); /* pressed more than 0.1 mm */
  CHECK(tissue_batch_read_field(b, 7, TISSUE_FIELD_DISPLACEMENT, u, 3 * nodes) == TISSUE_BAD_ARGUMENT);
  CHECK(contains(tissue_last_error(), "scene 7 does not exist"));
  free(u);

  /* scene 1 twice as stiff: it starts again at rest and presses back harder */
  CHECK(tissue_batch_set_material(b, 1, "", 6000.0, NAN, NAN) == TISSUE_OK);
  CHECK(tissue_batch_reset(b, -1) == TISSUE_OK);
  CHECK(tissue_batch_step(b, 120, &running) == TISSUE_OK && running == 2);
  CHECK(tissue_batch_forces(b, f, 6) == TISSUE_OK);
  CHECK(sqrt(f[3] * f[3] + f[4] * f[4] + f[5] * f[5]) > 1.5 * f0);
  int failed = 1;
  CHECK(tissue_batch_scene_failed(b, 0, &failed) == TISSUE_OK && failed == 0);
  CHECK(strcmp(tissue_batch_failure(b, 0), "") == 0);
  CHECK(tissue_batch_set_material(b, 0, "liver", 5000.0, NAN, NAN) == TISSUE_BAD_ARGUMENT);
  CHECK(contains(tissue_last_error(), "no material 'liver'"));
  CHECK(tissue_batch_reset(b, 5) == TISSUE_BAD_ARGUMENT);
  CHECK(tissue_batch_step(NULL, 1, NULL) == TISSUE_BAD_ARGUMENT);
  tissue_batch_close(b);
  tissue_batch_close(NULL);
}

/* "@kidney-fat" after its probe has pressed 2.5 mm into the fat layer (its
 * scripted path touches at 100 ticks): every body contact is a node of one
 * body inside a triangle of the other, its depth finite and >= 0; NULL
 * arrays are skipped; a capacity below the count is refused naming both,
 * with nothing written; the bare kidney, one body, has none. */
static void body_contact_checks(void) {
  tissue_simulation* sim = NULL;
  if (tissue_open_scene("@kidney-fat", "cpu", NULL, NULL, &sim) != TISSUE_OK) {
    fprintf(stderr, "tissue_open_scene(@kidney-fat): %s\n", tissue_last_error());
    ++failures;
    return;
  }
  int32_t count = -1;
  CHECK(tissue_body_contact_count(sim, &count) == TISSUE_OK && count == 0); /* before the first tick */
  CHECK(tissue_body_count(sim) == 2);
  CHECK(tissue_step(sim, 150) == TISSUE_OK);
  CHECK(tissue_body_contact_count(sim, &count) == TISSUE_OK);
  CHECK(count > 0);
  if (count <= 0) {
    tissue_close(sim);
    return;
  }
  const size_t n = (size_t)count;
  int32_t* nodes = malloc(n * sizeof *nodes);
  int32_t* triangles = malloc(3 * n * sizeof *triangles);
  int32_t* bodies = malloc(2 * n * sizeof *bodies);
  double* depths = malloc(n * sizeof *depths);
  double* again = malloc(n * sizeof *again);
  CHECK(nodes && triangles && bodies && depths && again);
  size_t written = 0;
  CHECK(tissue_body_contacts(sim, nodes, triangles, bodies, depths, n, &written) == TISSUE_OK && written == n);
  size_t first[2] = {0, 0}, size[2] = {0, 0};
  for (int b = 0; b < 2; ++b) CHECK(tissue_body_range(sim, b, &first[b], &size[b], NULL, NULL) == TISSUE_OK);
  int bad = 0;
  double deepest = 0;
  for (size_t i = 0; i < written; ++i) {
    const int32_t own = bodies[2 * i], other = bodies[2 * i + 1];
    if (own < 0 || own > 1 || other < 0 || other > 1 || own == other) {
      ++bad;
      continue;
    }
    if ((size_t)nodes[i] < first[own] || (size_t)nodes[i] >= first[own] + size[own]) ++bad;
    for (int k = 0; k < 3; ++k) {
      const size_t corner = (size_t)triangles[3 * i + k];
      if (corner < first[other] || corner >= first[other] + size[other]) ++bad;
    }
    if (!isfinite(depths[i]) || depths[i] < 0) ++bad;
    if (depths[i] > deepest) deepest = depths[i];
  }
  CHECK(bad == 0);
  CHECK(deepest > 1e-5); /* the probe pushes the layer into the kidney */
  /* NULL arrays are skipped */
  CHECK(tissue_body_contacts(sim, NULL, NULL, NULL, again, n, &written) == TISSUE_OK && written == n);
  CHECK(memcmp(again, depths, n * sizeof *depths) == 0);
  CHECK(tissue_body_contacts(sim, NULL, NULL, NULL, NULL, n, NULL) == TISSUE_OK);
  /* misuse */
  written = 99;
  again[0] = -1;
  CHECK(tissue_body_contacts(sim, NULL, NULL, NULL, again, n - 1, &written) == TISSUE_BAD_ARGUMENT);
  CHECK(written == 0 && again[0] == -1);
  CHECK(contains(tissue_last_error(), "capacity") && contains(tissue_last_error(), "is below the"));
  CHECK(tissue_body_contacts(NULL, nodes, triangles, bodies, depths, n, &written) == TISSUE_BAD_ARGUMENT);
  CHECK(contains(tissue_last_error(), "tissue_body_contacts: sim is NULL"));
  CHECK(tissue_body_contact_count(sim, NULL) == TISSUE_BAD_ARGUMENT);
  CHECK(contains(tissue_last_error(), "tissue_body_contact_count: count is NULL"));
  CHECK(tissue_body_contact_count(NULL, &count) == TISSUE_BAD_ARGUMENT);
  free(nodes);
  free(triangles);
  free(bodies);
  free(depths);
  free(again);
  tissue_close(sim);

  tissue_simulation* kidney = NULL;
  CHECK(tissue_open_scene("@kidney", "cpu", NULL, NULL, &kidney) == TISSUE_OK);
  if (kidney == NULL) return;
  CHECK(tissue_step(kidney, 3) == TISSUE_OK);
  count = -1;
  CHECK(tissue_body_contact_count(kidney, &count) == TISSUE_OK && count == 0);
  written = 99;
  CHECK(tissue_body_contacts(kidney, NULL, NULL, NULL, NULL, 0, &written) == TISSUE_OK && written == 0);
  tissue_close(kidney);
}

int main(void) {
  double nodes[3 * NN];
  int32_t tets[4 * NT];
  int32_t fixed[(N + 1) * (N + 1)];
  cube(nodes, tets);
  for (int j = 0; j <= N; ++j)
    for (int i = 0; i <= N; ++i) fixed[i + (N + 1) * j] = id(i, j, 0);
  tissue_mesh mesh = {nodes, NN, tets, NT, 3000.0, 0.4, 1000.0, fixed, (N + 1) * (N + 1), 3e-3};

  CHECK(strncmp(tissue_version(), "0.2.", 4) == 0);
  tissue_simulation* sim = NULL;
  tissue_status st = tissue_open_mesh(&mesh, "cpu", "double", &sim);
  if (st != TISSUE_OK) {
    fprintf(stderr, "tissue_open_mesh: %s\n", tissue_last_error());
    return 1;
  }
  CHECK(tissue_node_count(sim) == NN);
  CHECK(tissue_element_count(sim) == NT);
  CHECK(tissue_tool_count(sim) == 1);
  CHECK(fabs(tissue_tick_seconds(sim) - 1e-3) < 1e-12);
  /* a mesh is one body, "body", of every node and element */
  CHECK(tissue_body_count(sim) == 1);
  CHECK(tissue_body_name(sim, 0) != NULL && strcmp(tissue_body_name(sim, 0), "body") == 0);
  CHECK(tissue_body_name(sim, 1) == NULL);
  {
    size_t first = 99, count = 0, first_e = 99, count_e = 0;
    CHECK(tissue_body_range(sim, 0, &first, &count, &first_e, &count_e) == TISSUE_OK);
    CHECK(first == 0 && count == NN && first_e == 0 && count_e == NT);
    CHECK(tissue_body_range(sim, 0, NULL, NULL, NULL, &count_e) == TISSUE_OK);
    CHECK(tissue_body_range(sim, 1, &first, NULL, NULL, NULL) == TISSUE_BAD_ARGUMENT);
    CHECK(strstr(tissue_last_error(), "body 1 is out of range") != NULL);
  }

  /* Press the top centre 0.5 mm over 100 ticks, hold 300. */
  for (int k = 1; k <= 400; ++k) {
    const double s = k < 100 ? k / 100.0 : 1.0;
    const double tip[3] = {0.005, 0.005, 0.01 + 3e-3 - s * 5e-4};
    CHECK(tissue_set_tool_pose(sim, 0, tip, NULL) == TISSUE_OK);
    CHECK(tissue_step(sim, 1) == TISSUE_OK);
  }
  double f[3];
  CHECK(tissue_tool_force(sim, 0, f) == TISSUE_OK);
  CHECK(f[2] > 1e-4);
  CHECK(fabs(f[0]) < 0.05 * f[2] && fabs(f[1]) < 0.05 * f[2]);
  int32_t touching = 0;
  CHECK(tissue_tool_contact_count(sim, 0, &touching) == TISSUE_OK && touching > 0);
  CHECK(fabs(tissue_time(sim) - 0.4) < 1e-9);
  double u[3 * NN];
  CHECK(tissue_read_field(sim, TISSUE_FIELD_DISPLACEMENT, u, 3 * NN) == TISSUE_OK);
  CHECK(u[3 * id(1, 1, 2) + 2] < -2e-4); /* the top centre went down */
  CHECK(u[3 * id(1, 1, 0) + 2] == 0.0);  /* the base is fixed */

  /* Friction set live: the tool dragged 0.5 mm along x is held back by the tissue, at most mu N. */
  CHECK(tissue_tool_friction(sim, 0) == 0.0);
  CHECK(tissue_set_tool_friction(sim, 0, 0.5) == TISSUE_OK);
  CHECK(tissue_tool_friction(sim, 0) == 0.5);
  for (int k = 1; k <= 100; ++k) {
    const double tip[3] = {0.005 + k * 5e-6, 0.005, 0.01 + 3e-3 - 5e-4};
    CHECK(tissue_set_tool_pose(sim, 0, tip, NULL) == TISSUE_OK);
    CHECK(tissue_step(sim, 1) == TISSUE_OK);
  }
  CHECK(tissue_tool_force(sim, 0, f) == TISSUE_OK);
  CHECK(f[2] > 1e-4 && f[0] < -0.05 * f[2] && -f[0] <= 0.5 * f[2] * (1 + 1e-9));
  CHECK(tissue_set_tool_friction(sim, 0, -1.0) == TISSUE_BAD_ARGUMENT);
  CHECK(contains(tissue_last_error(), "friction = -1"));
  CHECK(tissue_set_tool_friction(sim, 2, 0.1) == TISSUE_BAD_ARGUMENT);
  CHECK(contains(tissue_last_error(), "tool 2"));
  CHECK(isnan(tissue_tool_friction(sim, 2)) && isnan(tissue_tool_friction(NULL, 0)));
  CHECK(tissue_set_tool_friction(NULL, 0, 0.1) == TISSUE_BAD_ARGUMENT);

  /* Misuse: a status and a message, never a crash. */
  CHECK(tissue_read_field(sim, TISSUE_FIELD_DISPLACEMENT, u, 7) == TISSUE_BAD_ARGUMENT);
  CHECK(contains(tissue_last_error(), "holds 7"));
  CHECK(tissue_read_field(sim, (tissue_field)9, u, 3 * NN) == TISSUE_BAD_ARGUMENT);
  CHECK(tissue_tool_force(sim, 3, f) == TISSUE_BAD_ARGUMENT);
  CHECK(contains(tissue_last_error(), "tool 3"));
  CHECK(tissue_step(sim, 0) == TISSUE_BAD_ARGUMENT);
  CHECK(tissue_tool_force(NULL, 0, f) == TISSUE_BAD_ARGUMENT);
  CHECK(contains(tissue_last_error(), "NULL"));
  const double nan_tip[3] = {0, NAN, 0};
  CHECK(tissue_set_tool_pose(sim, 0, nan_tip, NULL) == TISSUE_BAD_ARGUMENT);
  {
    const int32_t loaded[2] = {0, 1};
    const double pull[6] = {0, 0, 1e-3, 0, 0, 1e-3};
    CHECK(tissue_set_loads(sim, loaded, pull, 2) == TISSUE_OK);
    CHECK(tissue_set_loads(sim, NULL, pull, 2) == TISSUE_BAD_ARGUMENT);
    CHECK(contains(tissue_last_error(), "nodes"));
    const int32_t bad[1] = {1000000};
    CHECK(tissue_set_loads(sim, bad, pull, 1) == TISSUE_BAD_ARGUMENT);
    CHECK(contains(tissue_last_error(), "node 1000000 out of range"));
    CHECK(tissue_set_loads(sim, NULL, NULL, 0) == TISSUE_OK);
    CHECK(tissue_dissipated_energy(sim) == 0.0); /* an elastic mesh */
    CHECK(tissue_dissipated_energy(NULL) == 0.0);
  }
  CHECK(tissue_reset(sim) == TISSUE_OK);
  CHECK(tissue_time(sim) == 0.0);
  CHECK(tissue_tool_force(sim, 0, f) == TISSUE_OK);
  CHECK(strcmp(tissue_last_error(), "") == 0);

  /* A cut through the cube at x = 6 mm while it is pressed: more nodes and elements, the run goes on; a
     refused cut changes nothing; reset brings back the whole cube. */
  for (int k = 1; k <= 50; ++k) {
    const double tip[3] = {0.0075, 0.005, 0.01 + 3e-3 - 3e-4 * (k / 50.0)};
    CHECK(tissue_set_tool_pose(sim, 0, tip, NULL) == TISSUE_OK);
    CHECK(tissue_step(sim, 1) == TISSUE_OK);
  }
  {
    const double origin[3] = {0.006, -0.005, -0.005}, edge[3] = {0, 0.02, 0}, sweep[3] = {0, 0, 0.02};
    const double outside[3] = {0.05, 0, 0}, none[3] = {0, 0, 0};
    CHECK(tissue_cut(sim, outside, edge, sweep, NULL) == TISSUE_BAD_ARGUMENT);
    CHECK(contains(tissue_last_error(), "crosses no element"));
    CHECK(tissue_cut(sim, origin, none, sweep, NULL) == TISSUE_BAD_ARGUMENT);
    CHECK(contains(tissue_last_error(), "edge has zero length"));
    CHECK(tissue_cut(sim, origin, edge, sweep, "chop") == TISSUE_BAD_ARGUMENT);
    CHECK(tissue_cut(sim, NULL, edge, sweep, NULL) == TISSUE_BAD_ARGUMENT);
    CHECK(contains(tissue_last_error(), "tissue_cut: origin is NULL"));
    CHECK(tissue_node_count(sim) == NN);
    CHECK(tissue_cut(sim, origin, edge, sweep, NULL) == TISSUE_OK);
    CHECK(tissue_node_count(sim) > NN && tissue_element_count(sim) >= NT); /* nodes copied, maybe elements split */
    CHECK(tissue_step(sim, 20) == TISSUE_OK);
    CHECK(tissue_tool_force(sim, 0, f) == TISSUE_OK && f[2] > 0);
    CHECK(tissue_reset(sim) == TISSUE_OK);
    CHECK(tissue_node_count(sim) == NN && tissue_element_count(sim) == NT);
  }
  tissue_close(sim);
  tissue_close(NULL);

  tissue_simulation* none = NULL;
  CHECK(tissue_open_scene("/no/such/scene.xml", NULL, NULL, NULL, &none) == TISSUE_ERROR);
  CHECK(none == NULL && contains(tissue_last_error(), "/no/such/scene.xml"));
  CHECK(tissue_open_scene("@kidney", "vulkan", NULL, NULL, &none) == TISSUE_ERROR);
  CHECK(contains(tissue_last_error(), "vulkan"));
  tets[4 * 5 + 1] = 999; /* element 5 names a node that does not exist */
  CHECK(tissue_open_mesh(&mesh, "cpu", NULL, &none) != TISSUE_OK);
  CHECK(contains(tissue_last_error(), "5"));
  mesh.n_tets = -1;
  CHECK(tissue_open_mesh(&mesh, "cpu", NULL, &none) == TISSUE_BAD_ARGUMENT);

  body_contact_checks();
  batch_checks("cpu");
  batch_checks("cuda"); /* skipped where no GPU is usable */

  if (failures) fprintf(stderr, "%d checks failed\n", failures);
  else printf("all C interface checks passed\n");
  return failures ? 1 : 0;
}

// The command line: option values checked with messages naming the rule
// (whole numbers in digits, ranges, finite), the tick count and the work
// refusal of `tissue run`, and -- through the built program -- interrupted
// runs (SIGINT / SIGTERM: exit 130 / 143, the summary, a complete ticks.csv
// and frame series, no .part file), output folders (another run's
// outputs refused unless --overwrite, a folder in use refused), the version
// line and `tissue mesh` of a built-in scene.
#include <fcntl.h>
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <pugixml.hpp>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "apps/commands.hpp"
#include "apps/options.hpp"
#include "apps/run_session.hpp"
#include "apps/viewer/view_command.hpp"
#include "bench/bench.hpp"
#include "io/scene_xml.hpp"
#include "scene/checks.hpp"
#include "scene/validate.hpp"
#include "tests/cut_scenes.hpp"
#include "tests/temp_dir.hpp"

namespace tissue::app {
namespace {

namespace fs = std::filesystem;
using testing_support::TempDir;
using testing_support::slurp;



long lines(const std::string& text) {
  return std::count(text.begin(), text.end(), '\n');
}

/// The 2 x 2 x 1 cm block of docs/scene-format.md, its bottom fixed, pressed by the probe.
const char* kBlock = R"(<tissue-scene version="1">
  <mesh>
    <nodes>0 0 0  0.02 0 0  0 0.02 0  0.02 0.02 0  0 0 0.01  0.02 0 0.01  0 0.02 0.01  0.02 0.02 0.01</nodes>
    <elements>0 1 3 7  0 5 1 7  0 3 2 7  0 2 6 7  0 4 5 7  0 6 4 7</elements>
  </mesh>
  <material name="brain" E="3000" nu="0.45" rho="1000"/>
  <element-set material="brain" elements="all"/>
  <fixed box-min="-1 -1 -1" box-max="1 1 0"/>
  <tool name="probe" radius="0.001" device="scripted">
    <waypoint t="0" x="0.01" y="0.01" z="0.015"/>
    <waypoint t="0.1" x="0.01" y="0.01" z="0.008"/>
  </tool>
</tissue-scene>
)";

// ----------------------------------------------------------- option values

TEST(Options, WholeNumbers) {
  EXPECT_EQ(whole_number_error("12", 1, 100), "");
  EXPECT_EQ(whole_number_error("+12", 1, 100), "");
  EXPECT_EQ(whole_number_error("-5", 1, 100), "-5 is out of range: it must be in [1, 100]");
  EXPECT_EQ(whole_number_error("0", 1, 100), "0 is out of range: it must be in [1, 100]");
  EXPECT_EQ(whole_number_error("nan", 1, 100), "'nan' is not a whole number");
  EXPECT_EQ(whole_number_error("2.5", 1, 100), "'2.5' is not a whole number");
  EXPECT_EQ(whole_number_error("1e2", 1, 100), "'1e2' is not a whole number written in digits (write 100)");
  EXPECT_EQ(whole_number_error("1e12", 1, 1000),
            "'1e12' is not a whole number written in digits (and 1e+12 is above the most, 1000)");
  EXPECT_EQ(whole_number_error("99999999999999999999", 1, 100),
            "99999999999999999999 is out of range: it must be in [1, 100]");
}

TEST(Options, RealNumbers) {
  EXPECT_EQ(real_number_error("0.5", 0, 1, true), "");
  EXPECT_EQ(real_number_error("0", 0, 1, true), "0 is out of range: it must be in (0, 1]");
  EXPECT_EQ(real_number_error("1", 0, 1, false, true), "1 is out of range: it must be in [0, 1)");
  EXPECT_EQ(real_number_error("nan", 0, 1), "nan is not a finite number");
  EXPECT_EQ(real_number_error("-inf", 0, 1), "-inf is not a finite number");
  EXPECT_EQ(real_number_error("1s", 0, 1), "'1s' is not a number");
}

/// The error CLI11 raises for `tissue <args>` (empty when the values pass:
/// the command then runs and fails at once on the scene x.xml, which does
/// not exist -- its option values were accepted).
std::string parse_error(std::vector<std::string> args) {
  CLI::App app;
  int rc = 0;
  add_run_command(app, rc);
  add_reference_command(app, rc);
  add_bench_command(app, rc);
  add_tradeoff_command(app, rc);
  add_locking_command(app, rc);
  // these three are checked for refusals only: the command itself (meshing, a Hertz or convergence study)
  // is replaced, so that a value they accepted ends the parse at once instead of running it
  add_mesh_command(app, rc);
  add_hertz_command(app, rc);
  add_converge_command(app, rc);
  for (const char* name : {"mesh", "hertz", "converge"})
    app.get_subcommand(name)->callback([] { throw std::runtime_error("x.xml: cannot open the scene file"); });
  // `tissue view` hands its arguments to tissue-view: its options are the viewer's own
  viewer::add_view_options(*app.add_subcommand("view"), rc);
  std::reverse(args.begin(), args.end());
  try {
    app.parse(args);
  } catch (const CLI::ParseError& e) {
    return e.what();
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("x.xml: cannot open the scene file"), std::string::npos) << e.what();
  }
  return "";
}

// `tissue` runs on a headless GPU server: no display library among the
// libraries its executable needs (the viewer is tissue-view).
TEST(Program, NeedsNoDisplayLibrary) {
  FILE* p = popen((std::string("readelf -d '") + TISSUE_EXE + "' 2>&1").c_str(), "r");
  ASSERT_NE(p, nullptr);
  std::string out;
  char buf[512];
  while (fgets(buf, sizeof buf, p)) out += buf;
  ASSERT_EQ(pclose(p), 0) << out;
  std::vector<std::string> needed;
  std::istringstream lines(out);
  for (std::string line; std::getline(lines, line);)
    if (const auto at = line.find("Shared library: ["); at != std::string::npos)
      needed.push_back(line.substr(at + 17, line.find(']', at) - at - 17));
  ASSERT_FALSE(needed.empty()) << out;
  bool has_tbb = false;
  for (const std::string& lib : needed) {
    has_tbb = has_tbb || lib.find("libtbb") == 0;
    for (const char* display : {"libGL", "libEGL", "libOpenGL", "libGLX", "libGLEW", "libglfw", "libX", "libxcb",
                                "libwayland", "libimgui"})
      EXPECT_NE(lib.find(display), 0u) << TISSUE_EXE << " needs " << lib;
  }
  EXPECT_TRUE(has_tbb) << "the check reads the wrong list: " << out;  // the list is the one we think it is
}

TEST(Options, CommandsRefuseBadValues) {
  EXPECT_EQ(parse_error({"run", "x.xml", "--ticks", "100"}), "");
  EXPECT_EQ(parse_error({"run", "x.xml", "--ticks", "-5"}), "--ticks: -5 is out of range: it must be in [1, 1000000000000]");
  EXPECT_EQ(parse_error({"run", "x.xml", "--ticks", "nan"}), "--ticks: 'nan' is not a whole number");
  EXPECT_EQ(parse_error({"run", "x.xml", "--ticks", "1e12"}),
            "--ticks: '1e12' is not a whole number written in digits (write 1000000000000)");
  EXPECT_EQ(parse_error({"run", "x.xml", "--frames", "-3"}), "--frames: -3 is out of range: it must be in [0, 1000000]");
  EXPECT_EQ(parse_error({"run", "x.xml", "--time", "nan"}), "--time: nan is not a finite number");
  EXPECT_EQ(parse_error({"run", "x.xml", "--time", "-1"}), "--time: -1 is out of range: it must be in (0, 1000000000]");
  EXPECT_EQ(parse_error({"reference", "x.xml", "--tol", "0"}), "--tol: 0 is out of range: it must be in (0, 1)");
  EXPECT_EQ(parse_error({"reference", "x.xml", "--safety", "1.5"}),
            "--safety: 1.5 is out of range: it must be in (0, 1)");
  EXPECT_EQ(parse_error({"bench", "--min-seconds", "nan"}), "--min-seconds: nan is not a finite number");
  EXPECT_EQ(parse_error({"bench", "--batch", "1,2.5"}), "--batch: '2.5' is not a whole number");
  EXPECT_EQ(parse_error({"tradeoff", "x.xml", "--max-hold", "-1"}),
            "--max-hold: -1 is out of range: it must be in (0, 1000000]");
  EXPECT_EQ(parse_error({"tradeoff", "x.xml", "--meshes", "3000,-1"}),
            "--meshes: -1 is out of range: it must be in [0, 100000000]");
  EXPECT_EQ(parse_error({"locking", "--nu", "0.5"}), "--nu: 0.5 is out of range: it must be in (-1, 0.5)");
  EXPECT_EQ(parse_error({"locking", "--cells", "4,0"}), "--cells: 0 is out of range: it must be in [1, 64]");
  EXPECT_EQ(parse_error({"view", "x.xml", "--ticks", "-5"}), "--ticks: -5 is out of range: it must be in [0, 1000000000]");
  EXPECT_EQ(parse_error({"view", "x.xml", "--width", "0"}), "--width: 0 is out of range: it must be in [16, 16384]");
  EXPECT_EQ(parse_error({"view", "x.xml", "--fps", "nan"}), "--fps: nan is not a finite number");
  // outputs are checked before the work that would write them
  EXPECT_EQ(parse_error({"run", "x.xml", "--out", ""}), "--out: an empty folder name");
  EXPECT_EQ(parse_error({"reference", "x.xml", "--json", "/"}), "--json: / is a folder; give a file name");
  EXPECT_EQ(parse_error({"tradeoff", "x.xml", "--json", "/no/such/dir/t.json"}),
            "--json: /no/such/dir/t.json: the folder /no/such/dir does not exist");
}

// Values that ate the machine or gave an internal dump: each refused at the
// parse, naming the option, the value and the rule (an estimate where the
// rule is one).
TEST(Options, StudiesAndMeshingRefuseValuesBeyondTheirRange) {
  const std::string mesh_allowed = "; --target-tets is 0 (off) or a whole number of tets in [100, 2147483647]";
  EXPECT_EQ(parse_error({"mesh", "s.obj", "-o", "x.xml", "--remesh-edge", "-5"}),
            "--remesh-edge: -5 is not allowed: the edge is 0 (auto), -1 (never remesh) or a length > 0 m");
  EXPECT_EQ(parse_error({"mesh", "s.obj", "-o", "x.xml", "--target-tets", "1"}),
            "--target-tets: 1 tets are too few to represent a surface (the body would shrink to the few tets that "
            "span it)" + mesh_allowed);
  EXPECT_EQ(parse_error({"mesh", "s.obj", "-o", "x.xml", "--target-tets", "1e10"}),
            "--target-tets: '1e10' is not a whole number written in digits (and 1e+10 is above the most, "
            "2147483647)" + mesh_allowed);
  EXPECT_EQ(parse_error({"hertz", "--levels", "0"}),
            "--levels: 0 is out of range: it must be in [2, 100000] (cells per axis)");
  const std::string levels = parse_error({"hertz", "--levels", "100000"});  // reached 8 GB in 11 s
  EXPECT_EQ(levels.rfind("--levels: 100000 cells per axis make 6 x 100000^3 = 6e+15 tets, which need about 6e+09 GB "
                         "of memory (1000 bytes per tet in double); only ",
                         0),
            0u)
      << levels;
  EXPECT_NE(levels.find("GB are available: use at most "), std::string::npos) << levels;
  EXPECT_EQ(parse_error({"hertz", "--grading", "-3"}), "--grading: -3 is out of range: it must be in [1, 100]");
  EXPECT_EQ(parse_error({"hertz", "--radius", "1e300"}), "--radius: 1e300 is out of range: it must be in [1e-06, 1]");
  EXPECT_EQ(parse_error({"hertz", "--nu", "0.5"}), "--nu: 0.5 is out of range: it must be in (-1, 0.5)");
  EXPECT_EQ(parse_error({"hertz", "--E", "inf"}), "--E: inf is not a finite number");
  EXPECT_EQ(parse_error({"hertz", "--block", "0"}), "--block: 0 is out of range: it must be in (0, inf)");
  // a block of 1e9 contact radii stalled the relaxation; a core of 1e-9 inverted the graded cells
  EXPECT_EQ(parse_error({"hertz", "--block", "1e9"}).rfind("--block: a block of 1e9 contact radii is outside [10, 1000]", 0), 0u);
  EXPECT_EQ(parse_error({"hertz", "--core", "1e-9"}).rfind("--core: a core of 1e-9 contact radii is outside [0.25, 5]", 0), 0u);
  EXPECT_EQ(parse_error({"hertz", "--ratios", "5"}),
            "--ratios: delta / R = 5 is outside the range where Hertz's closed form holds, (0, 0.2]: it assumes the "
            "contact radius sqrt(R delta) small against R (at 0.2 it is already 0.45 R)");
  EXPECT_EQ(parse_error({"converge", "--tol", "1e-300"}),
            "--tol: 1e-300 is below what double precision resolves: the relative residual of the forces stalls at "
            "rounding noise above 1e-12; give a tolerance in [1e-12, 1)");
  EXPECT_EQ(parse_error({"converge", "--uniform", "-5"}), "--uniform: -5 is out of range: it must be in [100, 2147483647]");
}

// ---------------------------------------------------- tick count and work

TEST(RunPlan, TickCountFromTicksTimeOrPath) {
  RunOptions o;
  EXPECT_EQ(tick_count(o, 0.3, 1e-3), 300);  // the path
  o.time = 0.05;
  EXPECT_EQ(tick_count(o, 0.3, 1e-3), 50);
  o.ticks = 7;
  EXPECT_EQ(tick_count(o, 0.3, 1e-3), 7);
  EXPECT_EQ(tick_count(RunOptions{}, 0.0, 1e-3), 1);  // a one-waypoint path: one tick
  EXPECT_THROW(tick_count(RunOptions{}, 1.0, 1e-300), std::runtime_error);
}

TEST(RunPlan, WorkBeyondTheBoundIsRefusedUnlessForced) {
  scene::Scene s = io::parse_scene(kBlock, "block.xml", "");
  s.solver.tick = 1e-12;  // the 0.1 s path then lasts 1e11 ticks of one step each
  const TissueModel<double> m = scene::load_model(s);
  try {
    check_work(s, m, 200'000'000'000L, false);
    FAIL() << "expected a refusal";
  } catch (const std::runtime_error& e) {
    const std::string msg = e.what();
    for (const char* part : {"block.xml", "200000000000 ticks x 1 TLED steps x 6 elements", "1.2e+12", "--force",
                             "element", "material 'brain'"})
      EXPECT_NE(msg.find(part), std::string::npos) << part << " in: " << msg;
  }
  EXPECT_NO_THROW(check_work(s, m, 200'000'000'000L, true));
  EXPECT_NO_THROW(check_work(s, m, 100'000'000'000L, false));  // 6e11 element updates: within the bound
}

// A scene that needs far more steps per tick than any usual one (a density
// of 1e-6 here; E = 1e15, nu = 0.49999 alike) ran on for minutes after a
// warning: beyond 10 s of estimated work it is refused unless --force, with
// the plan's figures and the step's cause; a short run of it still goes.
TEST(RunPlan, ManyStepsPerTickAreRefusedBeyondTheirTimeUnlessForced) {
  scene::Scene s = io::parse_scene(kBlock, "block.xml", "");
  s.materials.front().rho = 1e-6;
  s.solver.mass_scaling = 0;
  const TissueModel<double> m = scene::load_model(s);
  const scene::WorkEstimate one = scene::estimate_work(m, s.solver.tick, 1);
  ASSERT_GT(one.steps_per_tick, scene::kManyStepsPerTick);
  ASSERT_LT(one.seconds, 1.0);
  const long within = long(scene::kMaxSecondsAtManySteps / one.seconds) - 1, beyond = 2 * within + 2;
  EXPECT_NO_THROW(check_work(s, m, within, false));
  try {
    check_work(s, m, beyond, false);
    FAIL() << "expected a refusal";
  } catch (const std::runtime_error& e) {
    const std::string msg = e.what();
    for (const std::string& part : std::vector<std::string>{
             fmt::format("block.xml: {:.0f} TLED steps per 0.001 s tick, more than the 100", one.steps_per_tick),
          fmt::format("{} ticks x {:.0f} steps", beyond, one.steps_per_tick), "element updates, about ",
          "on the cpu backend, beyond the 10 s", "--force", "rho = 1e-06 kg/m^3", "wave speed c = sqrt("})
      EXPECT_NE(msg.find(part), std::string::npos) << part << " in: " << msg;
  }
  EXPECT_NO_THROW(check_work(s, m, beyond, true));
  const std::string plan = work_plan(s, m, beyond);
  EXPECT_EQ(plan.rfind(fmt::format("plan: {} ticks x {:.0f} TLED steps = ", beyond, one.steps_per_tick), 0), 0u)
      << plan;
  EXPECT_NE(plan.find("element updates; about "), std::string::npos) << plan;
}

// ------------------------------------------------- the program, end to end

struct Child {
  pid_t pid = -1;
  std::string out, err;  ///< files holding its stdout and stderr
};

/// Starts the built `tissue` with `args`, its output into files in `dir`.
Child start(const TempDir& dir, const std::string& name, const std::vector<std::string>& args) {
  Child c;
  c.out = dir.file(name + ".out");
  c.err = dir.file(name + ".err");
  c.pid = fork();
  if (c.pid == 0) {
    const int o = open(c.out.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    const int e = open(c.err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    dup2(o, 1);
    dup2(e, 2);
    std::vector<char*> argv{const_cast<char*>(TISSUE_EXE)};
    for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    execv(TISSUE_EXE, argv.data());
    _exit(127);
  }
  return c;
}

/// Waits for the child; returns its exit code (128 + signal if a signal ended it).
int finish(const Child& c) {
  int status = 0;
  waitpid(c.pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

int run_tissue(const TempDir& dir, const std::string& name, const std::vector<std::string>& args) {
  return finish(start(dir, name, args));
}

/// Blocks until `path` holds at least `n` lines (the run has ticked), or
/// the child ended; false then.
bool wait_for_lines(const Child& c, const std::string& path, long n) {
  while (lines(slurp(path)) < n) {
    if (waitpid(c.pid, nullptr, WNOHANG) != 0) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return true;
}

/// Checks a folder left by an interrupted run: no .part file, ticks.csv
/// with one row per tick the summary reports, a .pvd listing frames that
/// all exist and parse, the last at the last tick's time.
void expect_complete_outputs(const std::string& dir, const std::string& summary) {
  for (const auto& e : fs::directory_iterator(dir))
    EXPECT_NE(e.path().extension(), ".part") << e.path();
  const size_t at = summary.find("haptic ticks");
  ASSERT_NE(at, std::string::npos) << summary;
  const long ticks = std::stol(summary.substr(summary.find_first_of("0123456789", at)));
  const std::string csv = slurp(dir + "/ticks.csv");
  EXPECT_EQ(lines(csv), ticks + 1);  // the header and one row per tick
  EXPECT_EQ(csv.back(), '\n');
  const std::string last_row = csv.substr(csv.rfind('\n', csv.size() - 2) + 1);
  EXPECT_EQ(std::stol(last_row), ticks - 1);  // the tick column counts from 0
  pugi::xml_document pvd;
  ASSERT_TRUE(pvd.load_file((dir + "/series.pvd").c_str()));
  int frames = 0;
  double last_time = -1;
  for (const auto& ds : pvd.child("VTKFile").child("Collection").children("DataSet")) {
    pugi::xml_document vtu;
    EXPECT_TRUE(vtu.load_file((dir + "/" + ds.attribute("file").value()).c_str())) << ds.attribute("file").value();
    last_time = ds.attribute("timestep").as_double();
    ++frames;
  }
  EXPECT_GE(frames, 1);  // the state at the stop is saved even before the first planned frame
  EXPECT_NEAR(last_time, 1e-3 * ticks, 1e-9);
}

TEST(Program, CommandsWithoutLoadsRefuseASceneWithLoads) {
  // tradeoff, reference and converge compare against a held-tool reference with no applied-load term
  TempDir t;
  std::string scene = kBlock;
  const std::string load = "  <load box-min=\"-1 -1 0.01\" box-max=\"1 1 1\" force=\"0 0 0.01\"/>\n";
  scene.insert(scene.find("</tissue-scene>"), load);
  std::ofstream(t.file("loaded.xml")) << scene;
  const int line = 1 + int(std::count(scene.begin(), scene.begin() + long(scene.find("<load")), '\n'));
  for (const std::string cmd : {"tradeoff", "reference", "converge"}) {
    EXPECT_EQ(run_tissue(t, cmd, {cmd, t.file("loaded.xml")}), 1) << cmd;
    const std::string err = slurp(t.file(cmd + ".err"));
    EXPECT_NE(err.find(fmt::format("loaded.xml:{}: <load>: `tissue {}` does not apply loads", line, cmd)),
              std::string::npos)
        << err;
  }
}

class Interrupted : public testing::TestWithParam<int> {};

TEST_P(Interrupted, RunStopsAtATickWritesEverythingAndExitsWith128PlusSignal) {
  const int sig = GetParam();
  TempDir t;
  std::ofstream(t.file("block.xml")) << kBlock;
  const std::string out = t.file("out");
  // a billion ticks: the run only ends by the signal; 1000 frames: none is due before it
  const Child c = start(t, "run", {"run", t.file("block.xml"), "--ticks", "1000000000", "--frames", "1000", "--out",
                                   out, "--quiet"});
  ASSERT_TRUE(wait_for_lines(c, out + "/ticks.csv.part", 3)) << slurp(c.err);
  // meanwhile the folder is in use
  EXPECT_EQ(run_tissue(t, "second", {"run", t.file("block.xml"), "--ticks", "5", "--out", out, "--overwrite"}), 1);
  EXPECT_NE(slurp(t.file("second.err")).find("in use by another running tissue process"), std::string::npos)
      << slurp(t.file("second.err"));
  kill(c.pid, sig);
  EXPECT_EQ(finish(c), 128 + sig);
  const std::string summary = slurp(c.out);
  EXPECT_NE(summary.find(fmt::format("of 1000000000 (stopped by {} at a tick boundary)",
                                     sig == SIGINT ? "SIGINT" : "SIGTERM")),
            std::string::npos)
      << summary;
  expect_complete_outputs(out, summary);

  // the folder now holds this run's outputs: refused, then replaced with --overwrite
  EXPECT_EQ(run_tissue(t, "again", {"run", t.file("block.xml"), "--ticks", "5", "--out", out}), 1);
  EXPECT_NE(slurp(t.file("again.err")).find("holds another run's outputs"), std::string::npos)
      << slurp(t.file("again.err"));
  EXPECT_EQ(run_tissue(t, "over", {"run", t.file("block.xml"), "--ticks", "5", "--frames", "5", "--out", out,
                                   "--overwrite", "--quiet"}),
            0)
      << slurp(t.file("over.err"));
  EXPECT_EQ(lines(slurp(out + "/ticks.csv")), 6);
  int vtus = 0;
  for (const auto& e : fs::directory_iterator(out)) vtus += e.path().extension() == ".vtu";
  EXPECT_EQ(vtus, 5);  // no frame of the first run beside the new series
}

INSTANTIATE_TEST_SUITE_P(Signals, Interrupted, testing::Values(SIGINT, SIGTERM),
                         [](const testing::TestParamInfo<int>& i) { return i.param == SIGINT ? "SIGINT" : "SIGTERM"; });

TEST(Program, BadInputsGetClearErrors) {
  TempDir t;
  std::ofstream(t.file("block.xml")) << kBlock;
  const auto error_of = [&](const std::vector<std::string>& args) {
    EXPECT_EQ(run_tissue(t, "bad", args), 1);
    return slurp(t.file("bad.err"));
  };
  EXPECT_NE(error_of({"run", t.file("")}).find("is a directory, not a scene file"), std::string::npos);
  std::string scene = kBlock;
  scene.replace(scene.find("t=\"0.1\""), 7, "t=\"nan\"");
  std::ofstream(t.file("nan.xml")) << scene;
  EXPECT_NE(error_of({"run", t.file("nan.xml")}).find("waypoint 1: t = nan is not a finite number"),
            std::string::npos);
  // a first word that is no command is named, with the commands
  EXPECT_EQ(run_tissue(t, "word", {"simulate", t.file("block.xml")}), 106);
  const std::string word = slurp(t.file("word.err"));
  EXPECT_NE(word.find("'simulate' is not a command; the commands are mesh, run"), std::string::npos) << word;
}

// `tissue cut` cuts the block through, reports the methods' rows and writes
// a scene that validates and runs; a bad blade is an error naming the rule.
TEST(Program, CutWritesASceneThatRuns) {
  TempDir t;
  std::ofstream(t.file("block.xml")) << kBlock;
  const std::vector<std::string> blade = {"--edge", "0,2,0", "--sweep", "0,0,2"};
  std::vector<std::string> args = {"cut", t.file("block.xml"), "--origin", "0.01,-1,-1", "-o", t.file("cut.xml")};
  args.insert(args.end(), blade.begin(), blade.end());
  ASSERT_EQ(run_tissue(t, "cut", args), 0) << slurp(t.file("cut.err"));
  EXPECT_NE(slurp(t.file("cut.out")).find("snap-split"), std::string::npos) << slurp(t.file("cut.out"));
  const scene::Scene cut = io::read_scene(t.file("cut.xml"));
  EXPECT_GT(cut.tets.size() / 4, 6u) << "the cube's six tets split";
  EXPECT_NO_THROW(scene::validate(cut));
  EXPECT_EQ(run_tissue(t, "run", {"run", t.file("cut.xml"), "--ticks", "5", "--quiet"}), 0) << slurp(t.file("run.err"));
  args = {"cut", t.file("block.xml"), "--origin", "0.01,-1"};
  args.insert(args.end(), blade.begin(), blade.end());
  EXPECT_EQ(run_tissue(t, "short", args), 1);
  EXPECT_NE(slurp(t.file("short.err")).find("--origin takes three numbers"), std::string::npos) << slurp(t.file("short.err"));
  args = {"cut", t.file("block.xml"), "--origin", "5,-1,-1"};
  args.insert(args.end(), blade.begin(), blade.end());
  EXPECT_EQ(run_tissue(t, "far", args), 1);
  EXPECT_NE(slurp(t.file("far.err")).find("crosses no element"), std::string::npos) << slurp(t.file("far.err"));
}

// `tissue run` on a scene with a blade: an 8 x 8 x 4 block of 2.5 mm cells
// cut by a blade pushed down through it with its button held (the stroke of
// tests/test_live_cut.cpp). It runs as a Session: the summary counts the
// cuts, and the last frame holds the cut mesh, the nodes the summary says.
TEST(Program, RunCutsWithABladeAndItsFramesHoldTheCutMesh) {
  TempDir t;
  const scene::Scene s = test::blade_scene(true, 5);
  io::write_scene(s, t.file("blade.xml"), true);
  const std::string out = t.file("out");
  ASSERT_EQ(run_tissue(t, "run", {"run", t.file("blade.xml"), "--frames", "2", "--out", out, "--quiet"}), 0)
      << slurp(t.file("run.err"));
  const std::string text = slurp(t.file("run.out"));
  const size_t at = text.find("cuts: ");
  ASSERT_NE(at, std::string::npos) << text;
  EXPECT_GT(std::stol(text.substr(at + 6)), 0) << text;
  const auto points = [](const std::string& vtu) {
    pugi::xml_document doc;
    EXPECT_TRUE(doc.load_file(vtu.c_str())) << vtu;
    long n = 0;
    for (pugi::xpath_node p : doc.select_nodes("//Piece")) n += p.node().attribute("NumberOfPoints").as_int();
    return n;
  };
  std::vector<std::string> frames;
  for (const auto& e : std::filesystem::directory_iterator(out))
    if (e.path().extension() == ".vtu") frames.push_back(e.path().string());
  std::sort(frames.begin(), frames.end());
  ASSERT_EQ(frames.size(), 2u);
  const size_t now = text.find("the mesh now ");
  ASSERT_NE(now, std::string::npos) << text;
  const long nodes = std::stol(text.substr(now + 13));
  EXPECT_GT(nodes, 9 * 9 * 5) << text;
  EXPECT_EQ(points(frames.back()), nodes) << "the last frame holds the cut mesh";
}

// `tissue run` prints what the run will cost before it builds the backend;
// the kidney at nu = 0.49999 (217 steps per tick, half a minute or more)
// is refused unless --force, naming its material.
TEST(Program, RunPrintsItsPlanAndRefusesTheStepBlowUp) {
  TempDir t;
  std::ofstream(t.file("block.xml")) << kBlock;
  ASSERT_EQ(run_tissue(t, "plan", {"run", t.file("block.xml"), "--ticks", "5", "--quiet"}), 0)
      << slurp(t.file("plan.err"));
  const std::string out = slurp(t.file("plan.out"));
  const size_t plan = out.find("plan: 5 ticks x 1 TLED steps = 5 steps on 6 elements = 30 element updates; about ");
  EXPECT_NE(plan, std::string::npos) << out;
  EXPECT_LT(plan, out.find("running 5 ticks")) << out;

  ASSERT_EQ(run_tissue(t, "k", {"mesh", "@kidney", "-o", t.file("k.xml"), "--nu", "0.49999"}), 0)
      << slurp(t.file("k.err"));
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_EQ(run_tissue(t, "nu", {"run", t.file("k.xml")}), 1);
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(20));  // refused, not run
  const std::string err = slurp(t.file("nu.err"));
  for (const char* part : {"TLED steps per 0.001 s tick, more than the 100", "element updates, about ",
                           "beyond the 10 s such a run may take without --force", "nu = 0.49999"})
    EXPECT_NE(err.find(part), std::string::npos) << part << "\n" << err;
  EXPECT_NE(slurp(t.file("nu.out")).find("plan: 1000 ticks x "), std::string::npos) << slurp(t.file("nu.out"));
}

// A stop caused by a value of the scene names that value: a load of 1e6 N on
// the 2 cm block inverts an element at once; the message blamed the tool.
TEST(Program, AStopNamesTheLikelyParameter) {
  TempDir t;
  std::string scene = kBlock;
  scene.insert(scene.find("</tissue-scene>"),
               "  <load box-min=\"-1 -1 0.01\" box-max=\"1 1 1\" force=\"0 0 -1e6\"/>\n");
  std::ofstream(t.file("load.xml")) << scene;
  EXPECT_EQ(run_tissue(t, "load", {"run", t.file("load.xml"), "--quiet"}), 1);
  const std::string err = slurp(t.file("load.err"));
  for (const char* part : {"(inverted or degenerate)", "likely cause:", "load box",
                           "total force 1e+06 N", "nominal stress F / L^2 = 2.5e+09 Pa", "check the force (N)"})
    EXPECT_NE(err.find(part), std::string::npos) << part << "\n" << err;
  EXPECT_EQ(err.find("a tool has most likely pressed deeper"), std::string::npos) << err;
}

/// A closed 2 cm cube as an OBJ file (outward triangles): 2.4e-3 m^2 of surface.
const char* kCubeObj = R"(v 0 0 0
v 0.02 0 0
v 0.02 0.02 0
v 0 0.02 0
v 0 0 0.02
v 0.02 0 0.02
v 0.02 0.02 0.02
v 0 0.02 0.02
f 1 3 2
f 1 4 3
f 5 6 7
f 5 7 8
f 1 2 6
f 1 6 5
f 4 8 7
f 4 7 3
f 1 5 8
f 1 8 4
f 2 3 7
f 2 7 6
)";

// `mesh --remesh-edge 1e-7` grew to 10.9 GB and `--remesh-edge 1e6` gave one
// tet: the edge's triangle count on the surface is estimated and refused
// beyond its bounds before any remeshing.
TEST(Program, MeshRefusesARemeshEdgeFarFromTheBodysSize) {
  TempDir t;
  std::ofstream(t.file("cube.obj")) << kCubeObj;
  const auto error_of = [&](const std::string& edge) {
    EXPECT_EQ(run_tissue(t, "mesh", {"mesh", t.file("cube.obj"), "-o", t.file("cube.xml"), "--remesh-edge", edge}), 1);
    return slurp(t.file("mesh.err"));
  };
  std::string err = error_of("1e-7");
  EXPECT_NE(err.find("--remesh-edge 1e-07 m: the surface of " + t.file("cube.obj") +
                     " (0.0024 m^2) would be remeshed into about 5.54e+11 triangles, more than the 5e+06 allowed"),
            std::string::npos)
      << err;
  EXPECT_NE(err.find("use an edge of at least 3.33e-05 m"), std::string::npos) << err;
  err = error_of("1e6");
  EXPECT_NE(err.find("--remesh-edge 1e+06 m: the surface of " + t.file("cube.obj") +
                     " (0.0024 m^2, extent 20.0 x 20.0 x 20.0 mm) would be remeshed into about 5.54e-15 triangles, "
                     "fewer than the 100 that represent a surface"),
            std::string::npos)
      << err;
  EXPECT_NE(err.find("use an edge of at most 0.00744 m"), std::string::npos) << err;
  EXPECT_FALSE(fs::exists(t.file("cube.xml")));
}

// The same --inclusion twice was meshed as two overlapping bodies and
// reported as a self-intersecting organ: refused before any file is read.
TEST(Program, MeshRefusesAnInclusionGivenTwice) {
  TempDir t;
  std::ofstream(t.file("cube.obj")) << kCubeObj;
  std::ofstream(t.file("tumour.obj")) << kCubeObj;  // its content is never read
  EXPECT_EQ(run_tissue(t, "twice", {"mesh", t.file("cube.obj"), "-o", t.file("x.xml"), "--inclusion",
                                    t.file("tumour.obj"), "--inclusion", t.file("tumour.obj") + ":E=5000"}),
            1);
  std::string err = slurp(t.file("twice.err"));
  EXPECT_NE(err.find("--inclusion " + t.file("tumour.obj") + ": the file is given twice (inclusions 1 and 2)"),
            std::string::npos)
      << err;
  EXPECT_EQ(err.find("intersects itself"), std::string::npos) << err;
  EXPECT_EQ(slurp(t.file("twice.out")).find("reading"), std::string::npos);  // before any file is read
  EXPECT_EQ(run_tissue(t, "organ", {"mesh", t.file("cube.obj"), "-o", t.file("x.xml"), "--inclusion",
                                    t.file("cube.obj")}),
            1);
  err = slurp(t.file("organ.err"));
  EXPECT_NE(err.find("--inclusion " + t.file("cube.obj") + ": the file is the organ's surface"), std::string::npos)
      << err;
  EXPECT_FALSE(fs::exists(t.file("x.xml")));
}

// `--quality 0` (no radius-edge bound: TetGen's q switch dropped) meshed without a word: it is documented as
// "none" and warned.
TEST(Program, MeshWarnsThatQualityZeroDropsTheBound) {
  TempDir t;
  std::ofstream(t.file("cube.obj")) << kCubeObj;
  EXPECT_EQ(run_tissue(t, "q0", {"mesh", t.file("cube.obj"), "-o", t.file("x.xml"), "--quality", "0", "--mesher",
                                 "tetgen"}),
            0);
  const std::string err = slurp(t.file("q0.err"));
  EXPECT_NE(err.find("warning: --quality 0: TetGen meshes with no radius-edge ratio bound"), std::string::npos) << err;
  EXPECT_TRUE(fs::exists(t.file("x.xml")));
}

/// Waits for c's TetGen child to appear, sends c SIGINT, expects exit 130
/// and returns what c wrote to stderr.
std::string interrupt_while_meshing(const Child& c) {
  const std::string children = fmt::format("/proc/{}/task/{}/children", c.pid, c.pid);
  bool meshing = false;
  for (int k = 0; k < 2000 && !meshing; ++k) {
    meshing = !slurp(children).empty();
    if (!meshing) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  EXPECT_TRUE(meshing) << "no TetGen child seen: " << slurp(c.err);
  kill(c.pid, SIGINT);
  EXPECT_EQ(finish(c), 130) << slurp(c.err);
  return slurp(c.err);
}

// SIGINT while TetGen meshed the built-in kidney (in a child process) was
// reported as "TetGen crashed (signal 9)", exit 1: it is an interruption,
// exit 130.
TEST(Program, InterruptWhileTetGenRunsExitsWith130) {
  TempDir t;
  // the kidney is meshed before the run
  const std::string err = interrupt_while_meshing(start(t, "kidney", {"run", "@kidney", "--ticks", "5", "--quiet"}));
  EXPECT_EQ(err.find("crashed"), std::string::npos) << err;
  EXPECT_NE(err.find("SIGINT"), std::string::npos) << err;
}

// `tissue mesh` stopped by SIGINT while TetGen meshes the kidney ends with 130, names the signal and writes
// nothing (it was killed by the signal's default action, with no word).
TEST(Program, InterruptWhileTissueMeshRunsExitsWith130AndWritesNothing) {
  TempDir t;
  const std::string out = t.file("k.xml");
  const std::string err = interrupt_while_meshing(start(t, "mesh", {"mesh", "@kidney", "-o", out}));
  EXPECT_NE(err.find("SIGINT"), std::string::npos) << err;
  EXPECT_FALSE(std::filesystem::exists(out)) << "nothing is written";
}

// `tradeoff --max-hold 1e-9` printed a table of unconverged rows: a hold
// shorter than the scene's tick is refused before the sweep.
TEST(Program, TradeoffRefusesAHoldShorterThanATick) {
  TempDir t;
  std::ofstream(t.file("block.xml")) << kBlock;
  EXPECT_EQ(run_tissue(t, "hold", {"tradeoff", t.file("block.xml"), "--max-hold", "1e-9"}), 1);
  const std::string err = slurp(t.file("hold.err"));
  EXPECT_NE(err.find("--max-hold 1e-09 s is shorter than one haptic tick of " + t.file("block.xml") +
                     " (0.001 s): the hold could not run a single tick"),
            std::string::npos)
      << err;
}

// `locking --cells 64` printed nothing in 120 s: the plan (the tets of each
// mesh and the cells^4 growth of the work) comes first, then each case as it
// is solved, with the next mesh's forecast.
TEST(Program, LockingPrintsItsPlanAndEachCaseAsItGoes) {
  TempDir t;
  ASSERT_EQ(run_tissue(t, "locking", {"locking", "--cells", "2,4"}), 0) << slurp(t.file("locking.err"));
  const std::string err = slurp(t.file("locking.err"));
  for (const char* part :
       {"locking: meshes of 2 (48 tets), 4 (384 tets) cells per side, each solved plain and IANP; the work grows as "
        "cells^4",
        "locking: 2 cells (48 tets), plain: ", "locking: 2 cells (48 tets), IANP: ",
        "; next: 4 cells, about ", " s per form (x 16, cells^4)", "locking: 4 cells (384 tets), plain: ",
        "locking: 4 cells (384 tets), IANP: "})
    EXPECT_NE(err.find(part), std::string::npos) << part << "\n" << err;
}

/// Standard output of a shell command, its last newline dropped; its exit
/// status in *status.
std::string shell_output(const std::string& command, int* status) {
  FILE* p = popen(command.c_str(), "r");
  if (p == nullptr) {
    *status = -1;
    return "";
  }
  std::string out;
  char buf[512];
  while (fgets(buf, sizeof buf, p)) out += buf;
  *status = pclose(p);
  if (!out.empty() && out.back() == '\n') out.pop_back();
  return out;
}

// `tissue --version` (no sub-command) and `tissue info` name the project
// version and the git commit of the build: a commit of the source tree's
// repository in a git checkout, "unknown" elsewhere.
TEST(Program, VersionNamesTheProjectVersionAndCommit) {
  TempDir t;
  ASSERT_EQ(run_tissue(t, "version", {"--version"}), 0) << slurp(t.file("version.err"));
  const std::string out = slurp(t.file("version.out"));
  EXPECT_EQ(out, version_line() + "\n");
  const std::string prefix = fmt::format("tissue {} (commit ", TISSUE_VERSION);
  ASSERT_EQ(out.rfind(prefix, 0), 0u) << out;
  ASSERT_EQ(out.substr(out.size() - 2), ")\n") << out;
  const std::string commit = out.substr(prefix.size(), out.size() - prefix.size() - 2);
  const std::string src = TISSUE_SOURCE_DIR;
  int status = 0;
  const std::string top = shell_output("git -C '" + src + "' rev-parse --show-toplevel 2>/dev/null", &status);
  if (status == 0 && fs::equivalent(top, src)) {
    ASSERT_NE(commit, "unknown") << "the source tree is a git checkout";
    shell_output("git -C '" + src + "' cat-file -e '" + commit + "^{commit}' 2>&1", &status);
    EXPECT_EQ(status, 0) << commit << " is not a commit of " << src;
  } else {
    EXPECT_EQ(commit, "unknown") << src << " is not a git checkout";
  }
  ASSERT_EQ(run_tissue(t, "info", {"info"}), 0) << slurp(t.file("info.err"));
  const std::string info = slurp(t.file("info.out"));
  EXPECT_EQ(info.substr(0, info.find('\n') + 1), out) << info;
}

// `tissue mesh @kidney` writes the built-in scene with the material options
// given and refuses, by name, the options that steer meshing a surface
// (they would be ignored); a bad material number is refused as a surface's is.
TEST(Program, MeshOfABuiltInSceneTakesMaterialOptionsAndRefusesMeshingOnes) {
  TempDir t;
  const std::string out = t.file("k.xml");
  EXPECT_EQ(run_tissue(t, "one", {"mesh", "@kidney", "-o", out, "--quality", "1.2"}), 1);
  EXPECT_NE(
      slurp(t.file("one.err")).find("@kidney: --quality applies to meshing a surface file, not to a built-in scene"),
      std::string::npos)
      << slurp(t.file("one.err"));
  EXPECT_EQ(run_tissue(t, "two", {"mesh", "@kidney-visco", "-o", out, "--unit", "mm", "--target-tets", "900"}), 1);
  EXPECT_NE(slurp(t.file("two.err"))
                .find("@kidney-visco: --unit, --target-tets apply to meshing a surface file, not to a built-in scene"),
            std::string::npos)
      << slurp(t.file("two.err"));
  EXPECT_EQ(run_tissue(t, "bad", {"mesh", "@kidney", "-o", out, "--E", "-5"}), 1);
  EXPECT_NE(slurp(t.file("bad.err")).find("@kidney: material 'kidney': Young's modulus E = -5 Pa must be > 0"),
            std::string::npos)
      << slurp(t.file("bad.err"));
  EXPECT_FALSE(fs::exists(out));

  ASSERT_EQ(run_tissue(t, "good", {"mesh", "@kidney-visco", "-o", out, "--E", "5000", "--rho", "1100"}), 0)
      << slurp(t.file("good.err"));
  const scene::Scene s = io::read_scene(out);
  ASSERT_EQ(s.materials.size(), 1u);
  const scene::Material& m = s.materials[0];
  EXPECT_EQ(m.name, "kidney");
  EXPECT_EQ(m.form, scene::Material::Form::YoungPoisson);
  EXPECT_DOUBLE_EQ(m.a, 5000);
  EXPECT_DOUBLE_EQ(m.b, 0.45);  // --nu not given: the built-in value
  EXPECT_DOUBLE_EQ(m.rho, 1100);
  EXPECT_EQ(m.prony.size(), 2u);  // still the viscoelastic kidney
}

// tissue bench --tick-dt-safety compares the haptic tick at several step
// margins in one run: each row names its margin and the steps per tick it
// gave (the kidney: 3 at 0.9, the previous default; 4 at 0.8, today's).
TEST(Bench, TickRowsCompareStepMarginsInOneRun) {
  bench::BenchOptions o;
  o.quick = true;
  o.precisions = {Precision::Float};
  o.sizes = {};
  o.tick_dt_safety = {0.9, 0.8};
  std::vector<std::pair<double, long>> seen;
  for (const std::string& row : bench::run_bench(o)) {
    if (row.find("\"haptic_tick\"") == std::string::npos) continue;
    const auto number = [&](const std::string& key) {
      const size_t k = row.find("\"" + key + "\": ");
      EXPECT_NE(k, std::string::npos) << row;
      return std::stod(row.substr(k + key.size() + 4));
    };
    seen.emplace_back(number("dt_safety"), std::lround(number("steps_per_tick")));
    EXPECT_GT(number("tick_ms_p50"), 0) << row;
    EXPECT_GT(number("reduce_ms_p50"), 0) << row;  // the reduction alone
  }
  const std::vector<std::pair<double, long>> want = {{0.9, 3}, {0.8, 4}, {0.9, 3}, {0.8, 4}};  // depth 5, then all
  EXPECT_EQ(seen, want);
}

// tissue bench --cut: only the live-cut row, the kidney cut four times
// while pressed, each cut timed and the cut mesh's tick after; --cut with
// the options of the other rows is refused, naming both.
TEST(Bench, TheLiveCutRowCutsThePressedKidneyAndTimesIt) {
  bench::BenchOptions o;
  o.quick = true;
  o.cut = true;
  o.precisions = {Precision::Float};
  const std::vector<std::string> rows = bench::run_bench(o);
  ASSERT_EQ(rows.size(), 1u);
  const std::string& row = rows[0];
  const auto number = [&](const std::string& key) {
    const size_t k = row.find("\"" + key + "\": ");
    EXPECT_NE(k, std::string::npos) << row;
    return k == std::string::npos ? std::nan("") : std::stod(row.substr(k + key.size() + 4));
  };
  EXPECT_NE(row.find("\"live_cut\""), std::string::npos) << row;
  EXPECT_EQ(number("cuts"), 4.0);
  EXPECT_GT(number("elements_after"), number("elements_before"));
  EXPECT_GT(number("cut_ms_median"), 0);
  EXPECT_GE(number("cut_ms_max"), number("cut_ms_median"));
  EXPECT_GT(number("tick_ms_p99_after"), 0);
  EXPECT_GT(number("dt_crit_after_over_before"), 0.25);
  EXPECT_EQ(parse_error({"bench", "--cut", "--batch", "4"}), "--batch excludes --cut");
  EXPECT_EQ(parse_error({"bench", "--cut", "--scene", "@kidney"}), "--scene excludes --cut");
}

TEST(Bench, LawRowsNameTheirLaw) {
  bench::BenchOptions o;
  o.quick = true;
  o.precisions = {Precision::Float};
  o.sizes = {"kidney"};
  o.laws = {"neo-hookean", "visco", "fibre-visco"};
  std::vector<std::string> whole, tick;
  for (const std::string& row : bench::run_bench(o)) {
    // every row says how its kernels divide: the cpu backend in IEEE arithmetic
    EXPECT_NE(row.find("\"float_math\": \"ieee\""), std::string::npos) << row;
    const size_t k = row.find("\"law\": \"");
    if (k == std::string::npos) continue;
    const std::string law = row.substr(k + 8, row.find('"', k + 8) - (k + 8));
    if (row.find("\"tled_whole_mesh\"") != std::string::npos) whole.push_back(law);
    if (row.find("\"haptic_tick\"") != std::string::npos) tick.push_back(law);
  }
  EXPECT_EQ(whole, o.laws);
  const std::vector<std::string> twice = {"neo-hookean", "visco", "fibre-visco", "neo-hookean", "visco", "fibre-visco"};
  EXPECT_EQ(tick, twice);  // depth 5, then all
  o.laws = {"maxwell"};
  EXPECT_THROW(bench::run_bench(o), std::invalid_argument);
}

// The kidney's whole mesh with a tool set 1 m away: a row of its own whose
// contact-stage cost is the difference of the two step rates.
TEST(Bench, ToolRowTimesTheContactStage) {
  bench::BenchOptions o;
  o.quick = true;
  o.precisions = {Precision::Float};
  o.sizes = {"kidney"};
  const auto number = [](const std::string& row, const std::string& key) {
    const size_t k = row.find("\"" + key + "\": ");
    return k == std::string::npos ? std::nan("") : std::stod(row.substr(k + key.size() + 4));
  };
  double whole = 0, with_tool = 0, stage = std::nan("");
  int contact_rows = 0;
  for (const std::string& row : bench::run_bench(o)) {
    if (row.find("\"contact_step\"") != std::string::npos) {  // the slab's stage share is timed too
      ++contact_rows;
      EXPECT_TRUE(std::isfinite(number(row, "contact_stage_us_per_step"))) << row;
    }
    if (row.find("\"tled_whole_mesh\"") != std::string::npos) whole = number(row, "steps_per_s");
    if (row.find("\"tled_whole_mesh_tool\"") != std::string::npos) {
      with_tool = number(row, "steps_per_s");
      stage = number(row, "contact_stage_us_per_step");
      EXPECT_EQ(number(row, "surface_triangles"), 3580.0) << row;
    }
  }
  EXPECT_EQ(contact_rows, 2);
  ASSERT_GT(whole, 0.0);
  ASSERT_GT(with_tool, 0.0);
  // the rows print 6 significant digits
  EXPECT_NEAR(stage, 1e6 * (1 / with_tool - 1 / whole), 1e6 * 1e-5 * (1 / with_tool + 1 / whole));
}

// tissue bench --scene: a scene file's haptic-tick rows beside the
// kidney's, named by the file and with its element count; a scene whose
// first tool has no path is refused naming the file.
TEST(Bench, SceneFilesGetHapticTickRowsOfTheirOwn) {
  TempDir t;
  std::ofstream(t.file("block.xml")) << kBlock;
  bench::BenchOptions o;
  o.quick = true;
  o.precisions = {Precision::Float};
  o.sizes = {};
  o.scenes = {t.file("block.xml")};
  std::vector<std::string> meshes;
  for (const std::string& row : bench::run_bench(o)) {
    if (row.find("\"haptic_tick\"") == std::string::npos) continue;
    const size_t k = row.find("\"mesh\": \"");
    ASSERT_NE(k, std::string::npos) << row;
    meshes.push_back(row.substr(k + 9, row.find('"', k + 9) - (k + 9)));
    if (meshes.back() == "block.xml") {
      EXPECT_NE(row.find("\"law\": \"scene\""), std::string::npos) << row;
      EXPECT_NE(row.find("\"elements\": 6"), std::string::npos) << row;
    }
  }
  const std::vector<std::string> want = {"kidney", "block.xml", "kidney", "block.xml"};  // depth 5, then all
  EXPECT_EQ(meshes, want);
  std::string pathless = kBlock;
  pathless.erase(pathless.find("    <waypoint"), pathless.find("  </tool>") - pathless.find("    <waypoint"));
  const std::string scripted = "device=\"scripted\"";
  pathless.replace(pathless.find(scripted), scripted.size(), "device=\"mouse\"");
  std::ofstream(t.file("pathless.xml")) << pathless;
  o.scenes = {t.file("pathless.xml")};
  try {
    bench::run_bench(o);
    ADD_FAILURE() << "a scene without a tool path was benched";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("pathless.xml: its first tool has no scripted path"), std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace tissue::app

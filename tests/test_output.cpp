// Output that no reader sees half-written and folders no two runs share:
// io/atomic_file (write under .part, rename), the tick log's .part file
// with whole flushed rows, io/output_dir's lock (held, refused, released by
// any process end, a killed one included) and its refusal / --overwrite of
// a previous run's outputs.
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <csignal>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <sstream>
#include <string>

#include "core/box_mesh.hpp"
#include "io/atomic_file.hpp"
#include "io/csv_log.hpp"
#include "io/output_dir.hpp"
#include "io/vtu_writer.hpp"
#include "tests/temp_dir.hpp"

namespace tissue {
namespace {

namespace fs = std::filesystem;
using testing_support::TempDir;
using testing_support::slurp;



/// Success when f throws std::runtime_error with every part in its message.
template <class F>
testing::AssertionResult throws_with(F&& f, std::initializer_list<std::string> parts) {
  try {
    f();
  } catch (const std::runtime_error& e) {
    const std::string msg = e.what();
    for (const std::string& p : parts)
      if (msg.find(p) == std::string::npos)
        return testing::AssertionFailure() << "message \"" << msg << "\" lacks \"" << p << "\"";
    return testing::AssertionSuccess();
  }
  return testing::AssertionFailure() << "no error";
}

const std::vector<std::string> kRunOutputs = {"ticks.csv", "series.pvd", "frame_*.vtu"};

// ------------------------------------------------------------ atomic files

TEST(AtomicFile, WritesWholeFileAndLeavesNoPart) {
  TempDir t;
  io::write_file_atomic(t.file("a.json"), "{\"x\": 1}\n");
  EXPECT_EQ(slurp(t.file("a.json")), "{\"x\": 1}\n");
  EXPECT_FALSE(fs::exists(t.file("a.json.part")));
  // replacing keeps the old version until the new one is complete
  io::AtomicTextFile f(t.file("a.json"));
  f.out() << "{\"x\": 2}\n";
  EXPECT_EQ(slurp(t.file("a.json")), "{\"x\": 1}\n");  // nothing written before commit
  f.commit();
  EXPECT_EQ(slurp(t.file("a.json")), "{\"x\": 2}\n");
}

TEST(AtomicFile, FailureNamesThePathAndLeavesTheOldFile) {
  TempDir t;
  EXPECT_TRUE(throws_with([&] { io::write_file_atomic(t.file("no/such/dir/a.csv"), "x"); },
                          {t.file("no/such/dir/a.csv"), "cannot open"}));
  // a folder where the file should go: the rename fails, the .part is removed
  fs::create_directories(t.file("taken"));
  fs::create_directories(t.file("taken/inside"));
  EXPECT_TRUE(throws_with([&] { io::write_file_atomic(t.file("taken"), "x"); }, {t.file("taken"), "rename"}));
  EXPECT_FALSE(fs::exists(t.file("taken.part")));
  EXPECT_TRUE(fs::is_directory(t.file("taken")));
}

TEST(AtomicFile, VtuSeriesLeavesOnlyCompleteFiles) {
  TempDir t;
  ModelInput in;
  box_mesh(in, 1, 1, 1, 0.01, 0.01, 0.01);
  in.materials = {{1000.0, 10000.0, 1000.0}};
  const TissueModel<double> m = build_model(in);
  Fields f;
  f.u.assign(3 * size_t(m.n_nodes), 0.0);
  f.f.assign(3 * size_t(m.n_nodes), 0.0);
  f.node_p.assign(m.n_nodes, 0.0);
  f.elem_J.assign(m.n_elems, 1.0);
  io::VtuSeries s(t.path());
  s.write(m, f, 0.0);
  s.write(m, f, 0.1);
  std::vector<std::string> names;
  for (const auto& e : fs::directory_iterator(t.path())) names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  EXPECT_EQ(names, (std::vector<std::string>{"frame_0000.vtu", "frame_0001.vtu", "series.pvd"}));
  EXPECT_NE(slurp(t.file("frame_0001.vtu")).find("</VTKFile>"), std::string::npos);
}

// ---------------------------------------------------------------- tick log

TEST(TickLogFile, RowsAreFlushedAsWholeLinesToPartThenRenamed) {
  TempDir t;
  const std::string path = t.file("ticks.csv");
  {
    io::TickLog log(path);
    EXPECT_FALSE(fs::exists(path));  // only complete logs carry the name
    TickReport r;
    for (long k = 0; k < io::TickLog::kFlushRows; ++k) {
      r.tick = k + 1;
      log.write(r);
    }
    // a block of rows reached the .part file without an explicit flush, each line whole
    const std::string part = slurp(io::part_path(path));
    EXPECT_EQ(std::count(part.begin(), part.end(), '\n'), io::TickLog::kFlushRows + 1);
    EXPECT_EQ(part.back(), '\n');
    log.close();
    EXPECT_FALSE(fs::exists(io::part_path(path)));
    EXPECT_TRUE(fs::exists(path));
    log.close();  // idempotent
  }
  const std::string text = slurp(path);
  EXPECT_EQ(std::count(text.begin(), text.end(), '\n'), io::TickLog::kFlushRows + 1);
}

TEST(TickLogFile, DestructorClosesTheLogOfARunThatThrew) {
  TempDir t;
  const std::string path = t.file("ticks.csv");
  try {
    io::TickLog log(path);
    log.write(TickReport{});
    throw std::runtime_error("the run stopped");
  } catch (const std::runtime_error&) {
  }
  const std::string text = slurp(path);
  EXPECT_EQ(std::count(text.begin(), text.end(), '\n'), 2);
  EXPECT_FALSE(fs::exists(io::part_path(path)));
}

// Several tools: the further tools' columns go through the same .part file;
// a tool count the log cannot take is refused before any file is created.
TEST(TickLogFile, SeveralToolsWriteTheirColumnsThroughThePartFile) {
  TempDir t;
  const std::string path = t.file("ticks.csv");
  {
    io::TickLog log(path, 2);
    TickReport r;
    r.n_tools = 2;
    r.tools[1].contact_nodes = 3;
    log.write(r);
    log.flush();
    EXPECT_FALSE(fs::exists(path));
    EXPECT_NE(slurp(io::part_path(path)).find(",tool2_grasp\n"), std::string::npos);
  }
  const std::string text = slurp(path);
  EXPECT_EQ(text.substr(0, text.find('\n')), io::TickLog::header(2));
  EXPECT_EQ(std::count(text.begin(), text.end(), '\n'), 2);
  EXPECT_FALSE(fs::exists(io::part_path(path)));
  EXPECT_THROW(io::TickLog(t.file("bad.csv"), 0), std::invalid_argument);
  EXPECT_FALSE(fs::exists(io::part_path(t.file("bad.csv"))));
  EXPECT_FALSE(fs::exists(t.file("bad.csv")));
}

// ----------------------------------------------------------- output folder

TEST(OutputFolder, PatternsMatchOneStar) {
  EXPECT_TRUE(io::matches_pattern("frame_0012.vtu", "frame_*.vtu"));
  EXPECT_TRUE(io::matches_pattern("frame_.vtu", "frame_*.vtu"));
  EXPECT_FALSE(io::matches_pattern("frame_0012.vtu.bak", "frame_*.vtu"));
  EXPECT_FALSE(io::matches_pattern("frame.vtu", "frame_*.vtu"));
  EXPECT_TRUE(io::matches_pattern("ticks.csv", "ticks.csv"));
  EXPECT_FALSE(io::matches_pattern("ticks.csv2", "ticks.csv"));
}

TEST(OutputFolder, CreatesAndLocksTheFolder) {
  TempDir t;
  const std::string dir = t.file("out/run1");
  {
    io::OutputFolder a(dir, kRunOutputs, false);
    EXPECT_TRUE(fs::is_directory(dir));
    EXPECT_EQ(a.file("ticks.csv"), dir + "/ticks.csv");
    // a second owner (another open file description, as another process has) is refused, naming the pid
    EXPECT_TRUE(throws_with([&] { io::OutputFolder b(dir, kRunOutputs, false); },
                            {dir, "in use by another running tissue process", fmt::format("pid {}", getpid())}));
    // --overwrite does not take a folder in use either
    EXPECT_TRUE(throws_with([&] { io::OutputFolder b(dir, kRunOutputs, true); }, {dir, "in use"}));
  }
  EXPECT_NO_THROW(io::OutputFolder(dir, kRunOutputs, false));  // released with its owner
}

TEST(OutputFolder, LockIsReleasedWhenTheOwnerIsKilled) {
  TempDir t;
  const std::string dir = t.file("out");
  int ready[2];
  ASSERT_EQ(pipe(ready), 0);
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {  // holds the folder, says so, then waits to be killed
    io::OutputFolder f(dir, kRunOutputs, false);
    const char c = 'x';
    if (::write(ready[1], &c, 1) != 1) _exit(2);
    pause();
    _exit(0);
  }
  char c = 0;
  ASSERT_EQ(::read(ready[0], &c, 1), 1);
  EXPECT_TRUE(throws_with([&] { io::OutputFolder b(dir, kRunOutputs, false); }, {"in use", std::to_string(child)}));
  kill(child, SIGKILL);
  int status = 0;
  waitpid(child, &status, 0);
  EXPECT_TRUE(WIFSIGNALED(status));
  EXPECT_NO_THROW(io::OutputFolder(dir, kRunOutputs, false));  // no stale lock after kill -9
  close(ready[0]);
  close(ready[1]);
}

TEST(OutputFolder, PreviousOutputsAreRefusedOrReplaced) {
  TempDir t;
  const std::string dir = t.path();
  t.write("ticks.csv", "old\n");
  t.write("series.pvd", "old\n");
  for (int k = 0; k < 12; ++k) t.write(fmt::format("frame_{:04d}.vtu", k), "old\n");
  t.write("frame_0012.vtu.part", "half");
  t.write("notes.txt", "mine\n");  // not an output: never touched
  EXPECT_TRUE(throws_with([&] { io::OutputFolder f(dir, kRunOutputs, false); },
                          {dir, "holds another run's outputs", "frame_0000.vtu", "and 11 more", "--overwrite"}));
  EXPECT_TRUE(fs::exists(t.file("ticks.csv")));  // refused: nothing removed
  {
    io::OutputFolder f(dir, kRunOutputs, true);
    EXPECT_EQ(f.removed(), 15);
  }
  std::vector<std::string> left;
  for (const auto& e : fs::directory_iterator(dir)) left.push_back(e.path().filename().string());
  std::sort(left.begin(), left.end());
  EXPECT_EQ(left, (std::vector<std::string>{".tissue.lock", "notes.txt"}));
  // the lock file alone is no previous output
  EXPECT_NO_THROW(io::OutputFolder(dir, kRunOutputs, false));
}

TEST(OutputFolder, AFileIsNoFolder) {
  TempDir t;
  t.write("plain", "x");
  EXPECT_TRUE(throws_with([&] { io::OutputFolder f(t.file("plain"), kRunOutputs, false); },
                          {t.file("plain"), "not a folder"}));
}

}  // namespace
}  // namespace tissue

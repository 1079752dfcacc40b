// The viewer's command line (tissue-view, which `tissue view` runs): its
// options registered on a CLI11 app.
#include <CLI/CLI.hpp>

#include <memory>

#include "apps/commands.hpp"
#include "apps/viewer/view_command.hpp"
#include "apps/options.hpp"
#include "apps/viewer/viewer.hpp"

namespace tissue::viewer {

void add_view_options(CLI::App& cmd_app, int& rc) {
  using app::load_scene_arg;
  using app::output_file;
  using app::real_number;
  using app::whole_number;
  CLI::App* cmd = &cmd_app;
  cmd->description(
      "Interactive viewer: the mouse (or a scripted or Phantom tool) presses the tissue at 1 kHz; "
      "--screenshot renders a picture offscreen instead");
  auto o = std::make_shared<viewer::ViewOptions>();
  cmd->add_option("scene", o->scene, "Scene XML file, or @kidney for the built-in kidney")->required();
  cmd->add_option("--backend", o->backend, "cpu | cuda (default: the scene's)");
  cmd->add_option("--precision", o->precision, "float | double (default: the scene's)");
  cmd->add_option("--depth", o->depth, "Region depth N (rings from the contact triangle) or 'all'");
  cmd->add_option("--device", o->device,
                  "mouse | scripted | phantom (default: mouse; for --screenshot the scene tool's device)");
  cmd->add_option("--screenshot", o->screenshot, "Render offscreen to this PNG (and a .json sidecar), then quit")
      ->check(output_file());
  cmd->add_option("--ticks", o->ticks, "With --screenshot: haptic ticks to run first (default: the tool path)")
      ->check(whole_number(0, 1'000'000'000));
  cmd->add_option("--width", o->width, "Window or picture width (pixels)")
      ->default_val(960)
      ->check(whole_number(16, 16384));
  cmd->add_option("--height", o->height, "Window or picture height (pixels)")
      ->default_val(720)
      ->check(whole_number(16, 16384));
  cmd->add_option("--gl", o->gl,
                  "window | hidden | egl (default: window; pictures: hidden under X, else egl without any X server)");
  cmd->add_option("--field", o->field,
                  "Colour the surface by a field, with a legend: none, displacement (|u|), pressure, J")
      ->default_val("none");
  cmd->add_option("--shading", o->shading, "smooth (per-vertex normals) | flat (per face)")->default_val("smooth");
  cmd->add_option("--hide", o->hide, "Leave out of the picture: comma list of tool, region, overlay");
  cmd->add_option("--mouse-events", o->mouse_events,
                  "With --screenshot and --device mouse: '<tick> wheel <n>; <tick> drag <x0>,<y0> <x1>,<y1>; "
                  "<tick> orbit <dx>,<dy>'");
  cmd->add_option("--seconds", o->seconds,
                  "Stop after this many seconds (0: when the window closes; needed with --gl egl without a picture)")
      ->check(real_number(0, 1e7));
  cmd->add_flag("--repeat", o->repeat, "With --device scripted: play the tool path over and over");
  cmd->add_flag("--scalpel", o->scalpel,
                "The first tool is a scalpel: a blade whose button (the right mouse button, a path's cut column) cuts "
                "(docs/cutting.md); the C key toggles it");
  cmd->add_option("--mouse-speed", o->mouse_speed, "Fastest the mouse moves the tool (m/s)")
      ->default_val(0.25)
      ->check(real_number(0, 100, true));
  cmd->add_option("--arrow-scale", o->arrow_scale, "Force arrow length in m per N (default: 1.5 organ diagonals)")
      ->check(real_number(0, 1e6, true));
  cmd->add_option("--fps", o->fps, "Most display frames per second")->default_val(60)->check(real_number(1, 10000));
  cmd->add_flag("--realtime,!--no-realtime", o->realtime,
                "Run the haptic thread with SCHED_FIFO priority (the default; needs CAP_SYS_NICE, else it runs at "
                "normal priority and says so)");
  cmd->callback([o, &rc] { rc = viewer::run_view(*o, load_scene_arg(o->scene)); });
}

}  // namespace tissue::viewer

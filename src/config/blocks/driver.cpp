// `driver`: which driver runs the robot (the simulator, or a driver process) and its settings
// (docs/CONFIG.md §driver).
#include "config/blocks/blocks.h"

namespace rcan::config::internal {
namespace {

Table<SimDriverConfig> sim_rows() {
  using S = Rows<SimDriverConfig>;
  return {
      S::field("wheel_base_m", Pos(), &SimDriverConfig::wheel_base_m),
      S::field("max_accel_mps2", Pos(), &SimDriverConfig::max_accel_mps2),
      S::field("max_angular_accel_radps2", Pos(), &SimDriverConfig::max_angular_accel_radps2),
      S::field("tick_hz", Int(1, 1000), &SimDriverConfig::tick_hz),
      S::field("telemetry_hz", Int(1, 100), &SimDriverConfig::telemetry_hz),
      S::field("arm_joints", Int(1, 16), &SimDriverConfig::arm_joints),
      S::check([](const At& sim, SimDriverConfig& sd, Ctx&) {
        if (sd.telemetry_hz > sd.tick_hz)
          fail(sim["telemetry_hz"].path, "must not exceed tick_hz", "out_of_range");
      }),
  };
}

Table<ProcessDriverConfig> process_rows() {
  using P = Rows<ProcessDriverConfig>;
  return {
      P::field("command", Arr(Str(), 256), &ProcessDriverConfig::command),
      P::path("socket", Str(107), &ProcessDriverConfig::socket),
      P::field("heartbeat_ms", Int(10, 10000), &ProcessDriverConfig::heartbeat_ms),
      P::field("heartbeat_timeout_ms", Int(20, 60000), &ProcessDriverConfig::heartbeat_timeout_ms),
      P::field("startup_timeout_ms", Int(100, 120000), &ProcessDriverConfig::startup_timeout_ms),
      P::field("restart_backoff_ms", Int(10, 60000), &ProcessDriverConfig::restart_backoff_ms),
      P::field("restart_backoff_max_ms", Int(10, 600000),
               &ProcessDriverConfig::restart_backoff_max_ms),
      P::field("max_linear_mps", Pos(), &ProcessDriverConfig::max_linear_mps),
      P::field("max_angular_radps", Pos(), &ProcessDriverConfig::max_angular_radps),
      P::field("linear_accel_mps2", NonNeg(), &ProcessDriverConfig::linear_accel_mps2),
      P::field("brake_decel_mps2", NonNeg(), &ProcessDriverConfig::brake_decel_mps2),
      P::check([](const At& at, ProcessDriverConfig& p, Ctx&) {
        if (p.heartbeat_timeout_ms <= p.heartbeat_ms)
          fail(at["heartbeat_timeout_ms"].path, "must exceed heartbeat_ms", "out_of_range");
        if (p.restart_backoff_max_ms < p.restart_backoff_ms)
          fail(at["restart_backoff_max_ms"].path, "must not be below restart_backoff_ms",
               "out_of_range");
      }),
  };
}

}  // namespace

Table<NodeConfig> driver_blocks() {
  using D = Rows<DriverConfig>;
  return {Rows<NodeConfig>::block(
      "driver",
      Table<DriverConfig>{
          D::field("type", Enum({"sim", "process"}), &DriverConfig::type),
          D::block("sim", sim_rows(), &DriverConfig::sim),
          D::block("process", process_rows(), &DriverConfig::process),
          D::check([](const At& at, DriverConfig& d, Ctx&) {
            if (d.type == "process" && d.process.command.empty() && d.process.socket.empty())
              fail(at["process"].path, "driver.type process needs command or socket", "required");
          }),
      },
      &NodeConfig::driver)};
}

}  // namespace rcan::config::internal

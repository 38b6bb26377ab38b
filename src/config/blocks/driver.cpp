// `driver`: which driver runs the robot (only the simulator today) and its settings
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

}  // namespace

Table<NodeConfig> driver_blocks() {
  using D = Rows<DriverConfig>;
  return {Rows<NodeConfig>::block("driver",
                                  Table<DriverConfig>{
                                      D::field("type", Enum({"sim"}), &DriverConfig::type),
                                      D::block("sim", sim_rows(), &DriverConfig::sim),
                                  },
                                  &NodeConfig::driver)};
}

}  // namespace rcan::config::internal

// The profile (schemas/rcan-config.json) and OpenCastor (schemas/rcan-config.schema.json)
// blocks this node validates and keeps in NodeConfig::kept without reading them (docs/CONFIG.md
// §Kept blocks). Their aliases of this node's keys (physics.type, reactive.min_obstacle_m, …)
// are read by the rows of those keys.
#include "config/blocks/blocks.h"

namespace rcan::config::internal {
namespace {

using R = Rows<NodeConfig>;

SP bridge() {
  return Obj({{"type", Str(128)},
              {"notes", Str(65536)},
              {"hostname", Str(256)},
              {"host", Str(256)},
              {"username", Str(256)},
              {"client_name", Str(256)},
              {"ros_domain_id", Int(0, 232)},
              {"namespace", Str(256)},
              {"cmd_vel_topic", Str(256)},
              {"odom_topic", Str(256)},
              {"scan_topic", Str(256)},
              {"nav2_action", Str(256)},
              {"waypoint_action", Str(256)},
              {"map_frame", Str(256)},
              {"base_frame", Str(256)},
              {"launch_package", Str(256)},
              {"launch_file", Str(256)},
              {"launch_args", Free()},
              {"ros_driver", Str(256)},
              {"fri_client_ip", Str(256)},
              {"fri_port", Int(1, 65535)},
              {"fri_library", Str(256)},
              {"fri_version", Str(64)},
              {"rtde_port", Int(1, 65535)},
              {"dashboard_port", Int(1, 65535)},
              {"recipe_file", Str(1024)}});
}

SP physics() {
  return Obj({{"type", Enum({"differential_drive", "ackermann", "serial_manipulator",
                             "parallel_manipulator", "holonomic", "custom", "mecanum",
                             "four_wheel_drive", "self_balancing", "omni"})},
              {"dof", Int(1, 1000)},
              {"chassis", Obj({{"wheel_base_mm", NonNeg()},
                               {"wheelbase_mm", NonNeg()},
                               {"track_width_mm", NonNeg()},
                               {"wheel_radius_mm", NonNeg()}})},
              {"kinematics", Arr(Obj({{"id", Str(128)},
                                      {"length_mm", NonNeg()},
                                      {"mass_g", NonNeg()},
                                      {"axis", Enum({"x", "y", "z"})},
                                      {"limits_deg", Arr(Num(), 2)}},
                                     {"id", "length_mm", "axis"}),
                                 64)}});
}

SP drivers() {
  return Arr(Obj({{"id", Str(128)},
                  {"link_id", Str(128)},
                  {"protocol", Str(128)},
                  {"port", Either({Int(0, 65535), Str(256)})},
                  {"address", Str(256)},
                  {"frequency", Int(0, 100'000'000)},
                  {"baud_rate", Int(0, 100'000'000)},
                  {"hardware_id", Int(0, 1'000'000)}},
                 {"protocol"}),
             64);
}

SP reactive() {
  return Obj({{"hailo_vision", Bool()},
              {"hailo_confidence", Num(0.0, 1.0)},
              {"hailo_model_path", Str(1024)},
              {"hailo_stop_distance_m", NonNeg()},
              {"hailo_warn_distance_m", NonNeg()},
              {"hailo_calibration", NonNeg()},
              {"min_obstacle_m", NonNeg()},  // read by agent.min_obstacle_m
              {"fallback_provider", Obj({{"provider", Str(128)}, {"model", Str(256)}})}});
}

SP learner() {
  return Obj({{"enabled", Bool()},
              {"provider", Str(128)},
              {"model", Str(256)},
              {"cadence", Str(64)},
              {"cadence_n", Int(1, 1'000'000)},
              {"max_retries", Int(0, 1000)},
              {"auto_apply_config", Bool()},
              {"auto_apply_behavior", Bool()},
              {"auto_apply_code", Bool()}});
}

SP camera() {
  return Obj({{"type", Str(128)},
              {"resolution", Arr(Int(1, 100'000), 2)},
              {"framerate", Int(1, 10'000)},
              {"depth_enabled", Bool()},
              {"fps", Int(1, 10'000)},
              {"imu_enabled", Bool()}});
}

}  // namespace

Table<NodeConfig> profile_blocks() {
  SP channel = Free();  // OpenCastor channels carry provider-specific credentials keys
  return {
      // profile style
      R::schema_only("bridge", bridge()),
      R::schema_only(
          "messaging",
          Obj({{"whatsapp", Obj({{"enabled", Bool()}, {"recipient", Str(256)}})},
               {"slack",
                Obj({{"enabled", Bool()}, {"channel", Str(256)}, {"webhook_url", Str(2048)}})}})),
      // OpenCastor style
      R::schema_only("physics", physics()),  // type and dof: read by robot.type, robot.dof
      R::schema_only("drivers", drivers()),
      R::schema_only("network", Obj({{"telemetry_stream", Bool()},
                                     {"sim_to_real_sync", Bool()},
                                     {"allow_remote_override", Bool()}})),
      R::schema_only("tiered_brain", Obj({{"planner_interval", Int(1, 1'000'000)},
                                          {"uncertainty_threshold", Num(0.0, 1.0)}})),
      R::schema_only("reactive", reactive()),
      R::schema_only("learner", learner()),
      R::schema_only("camera", camera()),
      R::schema_only("audio", Obj({{"tts_enabled", Bool()},
                                   {"engine", Str(128)},
                                   {"language", Str(64)},
                                   {"output_device", Str(256)}})),
      R::schema_only("channels", Obj({{"whatsapp", channel},
                                      {"telegram", channel},
                                      {"discord", channel},
                                      {"slack", channel}})),
      R::schema_only("agent_roster",
                     Arr(Obj({{"name", Str(128)}, {"enabled", Bool()}, {"config", Free()}},
                             {"name", "enabled"}),
                         256)),
      R::schema_only("connection", Free()),
      R::schema_only("notes", Either({Str(65536), Free()})),
      R::schema_only(
          "ros2", Obj({{"enabled", Bool()}, {"namespace", Str(256)}, {"domain_id", Int(0, 232)}})),
  };
}

}  // namespace rcan::config::internal

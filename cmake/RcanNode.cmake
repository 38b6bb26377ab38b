# The node (src/node, docs/ARCHITECTURE.md): one static library per folder, each linking only the
# folders below it, so that a call upwards does not link. From the bottom:
#   rcan_node_admission  who may send: tokens, revocation, replay, rate limits
#   rcan_node_vocabulary what every service speaks: the audit trail, the event bus
#   rcan_node_safety     the safety core, actuation, the simulated robot
#   rcan_node_control    who holds the robot: ControlService, sessions, ownership, consent, partitions
#   rcan_node_services   what the stages share (NodeServices)
#   rcan_node_discovery  mDNS (Avahi, loaded on first use), the robot directory
#   rcan_node_pipeline   the message pipeline and its stages
#   rcan_node_ai         the AI gates, thoughts, HITL
#   rcan_node_fleet      fleet ESTOP, swarm
#   rcan_node_api        Node (the front door), its HTTP routes and the dashboard
#   rcan_node_bindings   MQTT and UDP (gRPC: cmake/RcanGrpc.cmake)
# rcan_node is all eleven, for the programs that run a node (rcand, tests, benchmarks, fuzz targets).
rcan_add_library(rcan_node_admission src/node/admission authenticator.cpp injection.cpp rate_limit.cpp
  registry_feed.cpp registry_keys.cpp registry_revocations.cpp registry_trust.cpp
  registry_trust_link.cpp replay.cpp revocation.cpp token_cache.cpp)
target_link_libraries(rcan_node_admission PUBLIC rcan_runtime)

rcan_add_library(rcan_node_vocabulary src/node/vocabulary audit_trail.cpp refusal_ledger.cpp
  stop_backlog.cpp)
target_link_libraries(rcan_node_vocabulary PUBLIC rcan_node_admission rcan_runtime)

rcan_add_library(rcan_node_safety src/node/safety actuation.cpp latch_file.cpp safety.cpp safety_dispatch.cpp sim_robot.cpp)
target_link_libraries(rcan_node_safety PUBLIC rcan_config rcan_runtime)

rcan_add_library(rcan_node_control src/node/control consent.cpp control_grants.cpp control_machine.cpp
  control_service.cpp ownership.cpp partition.cpp sessions.cpp)
target_link_libraries(rcan_node_control PUBLIC rcan_node_vocabulary rcan_node_safety rcan_node_admission
  rcan_runtime)

rcan_add_library(rcan_node_services src/node/services node_services.cpp)
target_link_libraries(rcan_node_services PUBLIC rcan_node_control rcan_node_vocabulary rcan_node_safety
  rcan_node_admission rcan_transport rcan_config rcan_runtime)

rcan_add_library(rcan_node_discovery src/node/discovery avahi_dl.cpp mdns.cpp mdns_browse.cpp
  robot_directory.cpp)
target_link_libraries(rcan_node_discovery PUBLIC rcan_node_services rcan_config rcan_runtime ${CMAKE_DL_LIBS})
# Avahi (mDNS) is loaded on first use (avahi_dl.cpp): only its headers at build time.
target_include_directories(rcan_node_discovery SYSTEM PRIVATE ${AVAHI_INCLUDE_DIRS})

rcan_add_library(rcan_node_pipeline src/node/pipeline auth_stages.cpp authorize_stage.cpp
  dispatch_stage.cpp guard_stages.cpp guest_limits.cpp message_stages.cpp pipeline.cpp)
target_link_libraries(rcan_node_pipeline PUBLIC rcan_node_services rcan_node_admission rcan_runtime)

rcan_add_library(rcan_node_ai src/node/ai ai_services.cpp brain_layers.cpp gate_stages.cpp hitl.cpp
  thoughts.cpp)
target_link_libraries(rcan_node_ai PUBLIC rcan_node_pipeline rcan_node_services rcan_transport
  rcan_config rcan_runtime)

rcan_add_library(rcan_node_fleet src/node/fleet estop_ledger.cpp fleet.cpp swarm.cpp)
target_link_libraries(rcan_node_fleet PUBLIC rcan_node_pipeline rcan_node_services rcan_config rcan_runtime)

rcan_add_library(rcan_node_api src/node/api ai_routes.cpp audit_query.cpp control_routes.cpp node.cpp
  revocation_routes.cpp robots_routes.cpp route_table.cpp routes.cpp stage_order.cpp web_assets.cpp)
target_link_libraries(rcan_node_api PUBLIC rcan_node_ai rcan_node_discovery rcan_node_fleet
  rcan_node_pipeline rcan_node_services rcan_node_admission rcan_transport rcan_runtime)
# The operator dashboard (web/) is compiled into the node: one generated source holds its bytes.
file(GLOB_RECURSE RCAN_WEB_FILES CONFIGURE_DEPENDS ${PROJECT_SOURCE_DIR}/web/*)
set(RCAN_WEB_GENERATED ${PROJECT_BINARY_DIR}/generated/web_assets_data.cpp)
add_custom_command(OUTPUT ${RCAN_WEB_GENERATED}
  COMMAND ${CMAKE_COMMAND} -DWEB_DIR=${PROJECT_SOURCE_DIR}/web -DOUT=${RCAN_WEB_GENERATED}
          -P ${PROJECT_SOURCE_DIR}/cmake/embed_web.cmake
  DEPENDS ${RCAN_WEB_FILES} ${PROJECT_SOURCE_DIR}/cmake/embed_web.cmake
  COMMENT "Embedding the dashboard (web/)")
target_sources(rcan_node_api PRIVATE ${RCAN_WEB_GENERATED})

# grpc_module.cpp and grpc_server.cpp are in rcan_grpc (cmake/RcanGrpc.cmake).
rcan_add_library(rcan_node_bindings src/node/bindings mqtt_node.cpp udp_service.cpp)
target_link_libraries(rcan_node_bindings PUBLIC rcan_node_api rcan_node_fleet rcan_node_services
  rcan_transport rcan_config rcan_runtime)

add_library(rcan_node INTERFACE)
target_link_libraries(rcan_node INTERFACE rcan_node_bindings rcan_node_api rcan_node_fleet rcan_node_ai
  rcan_node_pipeline rcan_node_discovery rcan_node_services rcan_node_safety rcan_node_control
  rcan_node_vocabulary rcan_node_admission rcan_config rcan_transport rcan_mqtt ${CMAKE_DL_LIBS})

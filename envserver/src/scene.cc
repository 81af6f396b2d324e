#include "indrive/envserver/scene.h"

namespace indrive::env {

std::string_view class_name(SemanticClass cls) {
  switch (cls) {
    case SemanticClass::kUnlabeled:
      return "unlabeled";
    case SemanticClass::kRoad:
      return "road";
    case SemanticClass::kRoadLine:
      return "road_line";
    case SemanticClass::kSidewalk:
      return "sidewalk";
    case SemanticClass::kVehicle:
      return "vehicle";
    case SemanticClass::kBuilding:
      return "building";
    case SemanticClass::kVegetation:
      return "vegetation";
    case SemanticClass::kSky:
      return "sky";
  }
  return "unknown";
}

}  // namespace indrive::env

#include "indrive/learner/training_episodes.h"

#include <exception>
#include <utility>

#include "indrive/basics/log.h"

namespace indrive::learner {

TrainingEpisodes::TrainingEpisodes(std::filesystem::path path, TrainingRunLabels labels,
                                   std::string log_tag)
    : path_(std::move(path)), labels_(std::move(labels)), log_tag_(std::move(log_tag)) {}

void TrainingEpisodes::write(EpisodeRecord row) {
  try {
    if (!csv_) csv_.emplace(path_);
    row.method = labels_.method;
    row.eval_kind = "training";
    row.task = labels_.task;
    row.train_seed = labels_.train_seed;
    row.episode = static_cast<int>(csv_->rows());
    csv_->write(row);
  } catch (const std::exception& error) {
    if (!failed_) {
      INDRIVE_LOG(kError, log_tag_) << "training episodes are not recorded: " << error.what();
    }
    failed_ = true;
  }
}

}  // namespace indrive::learner

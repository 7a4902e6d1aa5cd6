#include "iceskate_native/control_loop.hpp"

#include <algorithm>
#include <cmath>
#include <optional>
#include <stdexcept>
#include <utility>

#include <Eigen/Geometry>

#include "iceskate_native/checks.hpp"
#include "iceskate_native/model_kinematics.hpp"
#include "iceskate_native/observation.hpp"

namespace iceskate_native
{

namespace
{

constexpr int kMaxSources = 64;  // SampleBlock::present has one bit per source

/// `kinematics` if it is a ModelKinematics that can adopt the passes of `dynamics`, else null.
ModelKinematics * adopting(Kinematics * kinematics, const Dynamics & dynamics)
{
  auto * model = dynamic_cast<ModelKinematics *>(kinematics);
  return model != nullptr && model->can_adopt_from(dynamics) ? model : nullptr;
}

/// Index in `events` of the latest transition at or before t [s] (-1: none).
std::int64_t last_event_at(const std::vector<TransitionRecord> & events, double t)
{
  auto last = static_cast<std::int64_t>(events.size()) - 1;
  while (last >= 0 && !(events[static_cast<std::size_t>(last)].t <= t)) {
    --last;
  }
  return last;
}

template <typename Derived>
void append(std::vector<double> & column, const Eigen::DenseBase<Derived> & values)
{
  for (Eigen::Index i = 0; i < values.size(); ++i) {
    column.push_back(values(i));
  }
}

}  // namespace

void SampleBlock::clear()
{
  count = 0;
  for_each_column(*this, [](const char *, auto & column, std::size_t) { column.clear(); });
  for (auto & column : efforts) {
    column.clear();
  }
}

ControlLoop::ControlLoop(
  HybridSimulator & simulator, Kinematics * kinematics, std::vector<Controller *> controllers,
  std::vector<Push> pushes, const Eigen::Vector3d & head_origin,
  const std::vector<std::pair<std::string, std::string>> & tf_pairs)
: simulator_(simulator),
  kinematics_(kinematics),
  model_kinematics_(adopting(kinematics, simulator.dynamics())),
  controllers_(std::move(controllers)),
  pushes_(std::move(pushes)),
  head_origin_(head_origin),
  held_target_(head_origin),
  frames_{"head_top"},
  outputs_(controllers_.size())
{
  for (const Controller * controller : controllers_) {
    if (controller == nullptr) {
      throw std::invalid_argument("a control loop's controller is missing (null)");
    }
  }
  if (kinematics_ == nullptr && !controllers_.empty()) {
    throw std::invalid_argument("a control loop with controllers needs their kinematics");
  }
  for (const Push & push : pushes_) {
    simulator_.dynamics().support_model(0, 0).frame(push.frame);  // invalid_argument if unknown
    if (!std::isfinite(push.start) || !std::isfinite(push.duration) || !push.force.allFinite()) {
      throw std::invalid_argument("a push needs a finite start, duration and force");
    }
  }
  if (!head_origin_.allFinite()) {
    throw std::invalid_argument("the head origin must be finite");
  }
  const auto frame_index = [this](const std::string & name) {
    if (name == "world") {
      return 0;  // placements_[0] is the head's; a world parent is the identity (sample())
    }
    for (int k = 0; k < 4; ++k) {  // invalid_argument if a support model lacks the frame
      simulator_.dynamics().support_model(k / 2, k % 2).frame(name);
    }
    const auto found = std::find(frames_.begin() + 1, frames_.end(), name);
    if (found != frames_.end()) {
      return static_cast<int>(found - frames_.begin());
    }
    frames_.push_back(name);
    return static_cast<int>(frames_.size()) - 1;
  };
  for (const auto & [parent, child] : tf_pairs) {
    if (child == "world") {
      throw std::invalid_argument("a /tf pair's child must be a link, not the world");
    }
    const int parent_index = frame_index(parent);
    tf_.emplace_back(parent_index, frame_index(child));
  }
  for (int k = 0; k < 4; ++k) {
    for (const std::string & name : frames_) {
      frame_ids_[static_cast<std::size_t>(k)].push_back(
        simulator_.dynamics().support_model(k / 2, k % 2).frame(name));
    }
  }
}

const std::vector<int> & ControlLoop::frame_ids(const Contact & contact) const
{
  return frame_ids_[static_cast<std::size_t>(contact.side * 2 + contact.pivot)];
}

int ControlLoop::run(int periods, SampleBlock & block)
{
  block.clear();
  error_ = nullptr;
  physics_failed_ = false;
  while (block.count < periods && simulator_.ended() == RunEnd::kNone) {
    try {
      step(block);
    } catch (...) {
      error_ = std::current_exception();
      break;
    }
  }
  return block.count;
}

std::size_t ControlLoop::source_index(SampleBlock & block, const std::string & name)
{
  for (std::size_t i = 0; i < block.sources.size(); ++i) {
    if (block.sources[i] == name) {
      return i;
    }
  }
  if (block.sources.size() >= kMaxSources) {
    throw std::invalid_argument("a control loop records at most 64 sources");
  }
  block.sources.push_back(name);
  block.efforts.emplace_back(static_cast<std::size_t>(block.count) * kCoordinates, 0.0);
  return block.sources.size() - 1;
}

bool ControlLoop::hold(const std::vector<ReceivedCommand> & commands, SampleBlock & block)
{
  error_ = nullptr;
  physics_failed_ = false;
  try {
    period(commands, block);
  } catch (...) {
    error_ = std::current_exception();
    return false;
  }
  return true;
}

void ControlLoop::step(SampleBlock & block)
{
  const HybridState & now = simulator_.state();
  const Observation obs = observation_of(now, simulator_.dynamics().mode(now.contact.mode));
  // the passes of the state, which the period's physics needs, unless the laws read the other
  // pivot's model (a flat sole: the toe's)
  if (model_kinematics_ != nullptr && obs.pivot == now.contact.pivot) {
    model_kinematics_->adopt(now.contact.side, now.contact.pivot, now.q, now.v,
                             simulator_.dynamics().state_passes(now.contact, now.q, now.v));
  }
  commands_.resize(controllers_.size());
  for (std::size_t k = 0; k < controllers_.size(); ++k) {  // what each node would send
    ControllerOutput & out = outputs_[k];
    out.clear();
    controllers_[k]->compute(obs, *kinematics_, out);
    ReceivedCommand & command = commands_[k];
    command.total = out.total();
    command.sources.resize(out.sources.size());
    command.efforts.resize(static_cast<Eigen::Index>(out.sources.size()), kCoordinates);
    for (std::size_t i = 0; i < out.sources.size(); ++i) {
      command.sources[i] = out.sources[i].source;
      command.efforts.row(static_cast<Eigen::Index>(i)) =
        out.sources[i].command.torque(obs.q, obs.v).transpose();
    }
    command.has_head_target = out.has_head_target;
    command.head_target = out.head_target;
  }
  period(commands_, block);
}

void ControlLoop::period(const std::vector<ReceivedCommand> & commands, SampleBlock & block)
{
  Dynamics & dynamics = simulator_.dynamics();
  const HybridState & now = simulator_.state();
  // the head observed at t_k and the /tf links at the sample's state, in one pass unless a
  // transition due at t_k changes the support or q (below)
  dynamics.frame_placements(now.contact, now.q, frame_ids(now.contact), placements_);
  const int observed_side = now.contact.side;
  const int observed_pivot = now.contact.pivot;
  const Vector18 observed_q = now.q;

  // the held sum of the commands of t_k (iceskate_sim.model.command.HeldCommand.of_controllers)
  Inputs inputs;
  inputs.has_impedance = true;
  const Eigen::Vector3d * target = &head_origin_;
  for (const ReceivedCommand & command : commands) {
    const JointCommand & total = command.total;
    inputs.tau += total.effort;
    if (total.has_impedance) {
      inputs.tau += total.stiffness.cwiseProduct(total.reference);
      inputs.stiffness += total.stiffness;
      inputs.damping += total.damping;
    }
    if (command.has_head_target && target == &head_origin_) {
      target = &command.head_target;
    }
  }
  const double t = now.t;
  for (const Push & push : pushes_) {
    if (push.active(t)) {
      inputs.push_frame = push.frame;
      inputs.push_force = push.force;
      break;
    }
  }

  try {  // the checks the binding of HybridSimulator::advance makes, with its words
    require_finite_vector(inputs.tau, kCoordinates, "tau", "[y0, q1..q17]");
    require_finite_vector(inputs.stiffness, kCoordinates, "stiffness", "[y0, q1..q17]");
    require_finite_vector(inputs.damping, kCoordinates, "damping", "[y0, q1..q17]");
    held_target_ = *target;
    simulator_.advance(inputs);
  } catch (...) {
    physics_failed_ = true;
    throw;
  }

  // the sample of t_k
  const HybridState & s = simulator_.start_state();
  const DynamicsResult & r = simulator_.start_result();
  const std::size_t row = static_cast<std::size_t>(block.count);
  std::uint64_t present = 0;
  const auto effort = [&](const std::string & source, const Vector18 & tau) {
    const std::size_t i = source_index(block, source);
    std::vector<double> & column = block.efforts[i];
    column.resize((row + 1) * kCoordinates, 0.0);
    for (int j = 0; j < kCoordinates; ++j) {
      column[row * kCoordinates + static_cast<std::size_t>(j)] = tau[j];
    }
    present |= std::uint64_t{1} << i;
  };
  for (const ReceivedCommand & command : commands) {
    for (std::size_t i = 0; i < command.sources.size(); ++i) {
      effort(command.sources[i], command.efforts.row(static_cast<Eigen::Index>(i)).transpose());
    }
  }
  if (!inputs.push_frame.empty()) {
    effort("push", dynamics.push_force(s.contact, s.q, inputs.push_frame, inputs.push_force));
  }
  for (auto & column : block.efforts) {  // sources that did not answer: 0
    column.resize((row + 1) * kCoordinates, 0.0);
  }
  block.present.push_back(present);
  if (s.contact.side != observed_side || s.contact.pivot != observed_pivot
      || s.q != observed_q) {  // moved at t_k: the links where the sample's state has them
    const Placement head = placements_[0];
    dynamics.frame_placements(s.contact, s.q, frame_ids(s.contact), placements_);
    placements_[0] = head;
  }
  sample(block, s, r, placements_[0], held_target_);
}

void ControlLoop::sample(
  SampleBlock & block, const HybridState & s, const DynamicsResult & r, const Placement & head,
  const Eigen::Vector3d & target) const
{
  const Mode & mode = simulator_.dynamics().mode(s.contact.mode);
  const bool q1_active = mode.q1_active;
  const Eigen::Matrix3d & rotation = head.rotation;
  block.t.push_back(s.t);
  block.t_exchange.push_back(s.t_exchange);
  block.t_touchdown.push_back(s.t_touchdown);
  block.heel_anchor_y.push_back(s.contact.heel_anchor_y);
  block.mode.push_back(s.contact.mode);
  block.side.push_back(s.contact.side);
  block.pivot.push_back(q1_active ? s.contact.pivot + 1 : 0);
  block.step_index.push_back(s.step_index);
  append(block.q, s.q);
  append(block.v, s.v);
  append(block.qdd, r.qdd);
  append(block.passive, r.passive);
  append(block.applied, r.applied);
  append(block.multipliers, r.multipliers);
  block.support_normal.push_back(r.support_normal);
  block.support_friction.push_back(r.support_friction);
  block.zmp_y.push_back(r.zmp_y);
  block.swing_clearance.push_back(std::min(r.swing_heel.z(), r.swing_toe_z));
  append(block.head_position, head.translation);
  append(block.head_orientation, Eigen::Quaterniond(rotation).coeffs());
  block.head_pitch.push_back(std::atan2(-rotation(1, 2), rotation(2, 2)));
  block.tf_pairs = tf_.size();
  for (const auto & [parent, child] : tf_) {
    const Placement & c = placements_[static_cast<std::size_t>(child)];
    if (parent == 0) {
      append(block.tf, c.translation);
      append(block.tf, Eigen::Quaterniond(c.rotation).coeffs());
      continue;
    }
    const Placement & p = placements_[static_cast<std::size_t>(parent)];
    append(block.tf, (p.rotation.transpose() * (c.translation - p.translation)).eval());
    append(block.tf, Eigen::Quaterniond(p.rotation.transpose() * c.rotation).coeffs());
  }
  append(block.head_target, target);
  const std::int64_t last = last_event_at(simulator_.events(), s.t);
  block.last_event.push_back(last);
  const GuardConstants & sole = simulator_.settings().constants;
  const double y0 = s.q[kY0];
  block.y0_active.push_back(mode.y0_active);
  block.q1_active.push_back(q1_active);
  block.zmp_inside_support.push_back(  // false for a NaN CoP (no support force)
    !q1_active && y0 + sole.sole_heel_y <= r.zmp_y && r.zmp_y <= y0 + sole.sole_toe_y);
  block.touched_down.push_back(!std::isnan(s.t_touchdown));
  const std::size_t first = block.active.size();
  block.active.resize(first + kCoordinates, 0);
  for (const int i : mode.active) {
    block.active[first + static_cast<std::size_t>(i)] = 1;
  }
  block.effort_total.resize(first + kCoordinates, 0.0);
  for (const auto & column : block.efforts) {
    for (std::size_t i = 0; i < kCoordinates; ++i) {
      block.effort_total[first + i] += column[first + i];
    }
  }
  const double last_t = last >= 0 ? simulator_.events()[static_cast<std::size_t>(last)].t : 0.0;
  for (const double time : {s.t, s.t_exchange, std::isnan(s.t_touchdown) ? 0.0 : s.t_touchdown,
                            last_t}) {
    block.stamps_ns.push_back(stamp_ns(time));
  }
  ++block.count;
}

void ControlLoop::live(SampleBlock & block)
{
  const HybridState & s = simulator_.state();
  const Inputs & held = simulator_.inputs();
  // iceskate_sim.model.command.HeldCommand.torque: bias - stiffness q - damping v
  const Vector18 tau =
    held.tau - held.stiffness.cwiseProduct(s.q) - held.damping.cwiseProduct(s.v);
  block.clear();
  block.sources.assign(1, "held");
  block.efforts.assign(1, std::vector<double>(tau.data(), tau.data() + kCoordinates));
  block.present.push_back(1);
  simulator_.dynamics().frame_placements(s.contact, s.q, frame_ids(s.contact), placements_);
  sample(block, s, simulator_.result(), placements_[0], held_target_);
}

Column column_of(const SampleBlock & block, const std::string & name)
{
  std::optional<Column> found;
  for_each_column(block, [&](const char * key, const auto & column, std::size_t width) {
    if (name == key) {
      found = Column{column.data(), column_type(column), width};
    }
  });
  if (found) {
    return *found;
  }
  const std::string prefix = "efforts.";
  if (name.compare(0, prefix.size(), prefix) == 0) {
    const std::string index = name.substr(prefix.size());
    if (!index.empty() && index.find_first_not_of("0123456789") == std::string::npos) {
      const std::size_t i = std::stoul(index);
      if (i < block.efforts.size()) {
        return Column{block.efforts[i].data(), Column::Type::kFloat64, kCoordinates};
      }
    }
  }
  throw std::invalid_argument("a sample block has no column '" + name + "'");
}

}  // namespace iceskate_native
